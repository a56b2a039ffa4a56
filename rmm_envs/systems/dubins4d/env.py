"""Dubins4D among circles: a reckless driver, a guardian that may take over, and lidar.

``Dubins4DGuarded-v0`` (blocking, fixed step) and ``Dubins4DParallel-v0`` (non-blocking: the
guardian's thinking time passes in the world).  This is the paper's parallel-autonomy case study
(Sec. IV-A, Table I), rebuilt on Gymnasium.

## Description

A car-like vehicle (:class:`rmm_envs.systems.dubins4d.dynamics.Dubins4D`) drives toward a circular goal among
``n_obstacles`` circular obstacles.  A built-in "reckless driver" (:class:`rmm_envs.systems.dubins4d.driver.
CLFDriver`, a CLF-QP) steers it to the goal and ignores the obstacles.  The agent is a
*guardian*: at every step it decides whether to take control and, if so, which control to apply.

## Dynamics

State ``(x, y, theta, v)``: ``x' = v cos theta, y' = v sin theta, theta' = u1, v' = u2`` with
``v`` held in ``[0, 2]`` m/s, integrated exactly for the step's zero-order-hold control.  The
arena is ``[-10, 10]^2`` m for generation only: leaving it is allowed (no walls), as in the paper.

## Action space

``Dict(active_ctrl=Discrete(2), turnrate_ctrl=Box(-0.25, 0.25, (1,)), accel_ctrl=Box(-0.5, 0.5,
(1,)))``.  ``active_ctrl = 0``: the driver controls this step (the other fields are ignored);
``1``: ``(turnrate_ctrl, accel_ctrl)`` is applied.  Continuous values outside their bounds are
**clipped** (as in the paper); NaN/inf, a wrong shape or type, a missing field, or an
``active_ctrl`` other than 0/1 raise ``ValueError`` naming the field.  Scalars and shape-``(1,)``
arrays are both accepted for the continuous fields.

## Observation space

``Box(17,)`` float32:

| index | observation                               | min  | max  |
|-------|-------------------------------------------|------|------|
| 0     | simulation time, s                        | 0    | inf  |
| 1     | goal x - x, m (world frame, not rotated)  | -inf | inf  |
| 2     | goal y - y, m                             | -inf | inf  |
| 3     | heading theta, rad, wrapped to [-pi, pi)  | -pi  | pi   |
| 4     | speed v, m/s                              | 0    | 2    |
| 5-16  | 12 ray lengths, m                         | 0    | 10   |

Ray ``i`` points at ``theta + 2 pi i / 12``: ray 0 straight ahead, ray 1 at +30 degrees (left),
ray 11 at -30 degrees (right).  Rays see obstacles only (exact circles), are capped at 10 m, and
read 0 from inside an obstacle.  The original left the heading unwrapped and its initial value
drawn from ``N(0, 1)``; we draw it uniformly on ``[-pi, pi)`` and always wrap it.

## Rewards

Sparse: ``+1`` on reaching the goal, ``-1`` on collision, ``0`` otherwise.  Goal and obstacle
contacts are checked exactly along the whole step's path (16 points, segments between them);
the first contact wins and a tie counts as a collision.

## Episode end

``terminated`` on goal or collision; ``truncated`` when simulated time reaches
``max_episode_sim_time`` (100 s).  As in the original, the state after a collision step is the
end of that step's path.

## Starting state

Obstacles: the first centred by ``N(0, 2^2)`` per axis, the others uniform on the arena, radii
``U(2, 5)`` (they may overlap).  Vehicle: position uniform on the arena and outside all
obstacles, heading ``U(-pi, pi)``, speed ``U(0, 2)``.  Goal: centre uniform on the arena,
radius ``U(0.1, 1)``, redrawn while it contains the vehicle or lies entirely inside an obstacle.

``reset(seed=..., options={"state": [x, y, theta, v], "goal": [x, y, r], "obstacles": [[x, y,
r], ...]})`` sets any subset explicitly; the rest is generated from the seed around what was
given, in the same order (obstacles, vehicle, goal) and by the same rules: a generated part is
redrawn until the vehicle is outside every obstacle and outside the goal and the goal is not
entirely inside an obstacle, against the given parts too (so ``{"state": ...}`` alone gets
obstacles that leave that state free, and ``{"goal": ...}`` alone a start outside that goal).
Given parts must obey the same rules among themselves: a state inside a given obstacle or
goal, or a goal entirely inside a given obstacle, raises ``ValueError`` naming the options
involved, as do wrong lengths, non-finite numbers, radii <= 0, a speed outside [0, 2] and
unknown keys.  Without options the draws are exactly those of generation.

## Risk labelling

The env follows the :class:`rmm_envs.risk.LabelledEnv` protocol: ``risk_scene()`` is the
episode's :class:`rmm_envs.scenes.Dubins4DScene` (the env's own collision checks and
observations use it too); ``sample_states(rng, n)`` draws states uniform over the arena x
``[-pi, pi)`` x ``[0, 2]``, rejecting those inside an obstacle; ``observe_states(states, rng)``
draws the simulated-time feature uniformly over ``[0, max_episode_sim_time]`` (the original
left it 0 in every training sample and met 0-100 s at run time).

## Info

Every step: ``sim_time``; ``state`` (the true state: **privileged**, for analysis and for
guardians that declare they use it); ``active`` and ``control`` (what was applied during the
step and whether the guardian applied it); ``cost`` (Safety-Gymnasium's per-step safety cost:
1.0 on the step that collides, else 0.0); ``nominal_control`` (also on ``reset``): the
driver's ``(u1, u2)`` at the state the returned observation shows, within the action space's
bounds, exactly what the driver applies if the guardian leaves it the next interval (a safety
filter's ``u_nom``; ``action_space.active(info["nominal_control"])`` drives as the driver
does, bit for bit).  On the last step also ``outcome`` (``"goal"``, ``"collision"``
or ``"timeout"``) and ``episode_stats`` (the statistics of the paper's Table I: ``n_env_steps``,
``n_active_ctrl_env_steps``, ``active_ctrl_sim_time``, ``cum_sim_time``, ``cum_compute_time``,
``avg_compute_time``, ``cum_reward``, ``cum_cost``, ``final_speed``, ``outcome``; not
``episode``, which Gymnasium's ``RecordEpisodeStatistics`` and SB3's ``Monitor`` write).

Privileged information is also available through :meth:`Dubins4DGuardedEnv.privileged`.

## Arguments

``gym.make("Dubins4DGuarded-v0", step_dt=0.1, n_rays=12, ray_length=10.0,
max_episode_sim_time=100.0, n_obstacles=5, obstacle_min_rad=2.0, obstacle_max_rad=5.0,
goal_min_rad=0.1, goal_max_rad=1.0, n_path_points=16, driver_params=None, clock=None,
render_mode=None, driver_solver="closed_form", starts="any", disturbances=None)``.
``disturbances``: sensor noise, actuation error, a drift of the position (``x``, ``y``),
impulses or a plant whose ``turn_gain``, ``accel_gain`` and ``v_max`` differ from the model's,
e.g. ``"obs-noise.rays=0.1; dyn-rate=0.2"`` (:mod:`rmm_envs.disturbances`; off by default,
drawn from the episode's seed).  ``starts="avoidable"`` redraws
a start (from the episode's seed) until some control avoids every obstacle, by the doomed test
of :mod:`rmm_envs.systems.dubins4d.doomed` (off by default: the paper's sampling keeps doomed starts; see
docs/concepts.md, Doomed starts).  ``clock`` ("wall", "cpu", "fixed:MS" or a
:class:`rmm_envs.clocks.Clock`) only measures the agent's compute time for the statistics in the
blocking env.  ``driver_solver``: how the driver's QP is solved, ``"closed_form"`` (exact, the
default) or ``"osqp"`` (the earlier solver, kept for checking; equal to about 1e-7).

``gym.make_vec("Dubins4DGuarded-v0", num_envs=N, vectorization_mode="vector_entry_point")``:
:class:`rmm_envs.systems.dubins4d.vector.Dubins4DCirclesVectorEnv`, ``N`` copies of this env
computed as arrays (sub-env ``i`` after ``reset(seed=s)`` is this env after ``reset(seed=s +
i)``, bit for bit).

``gym.make("Dubins4DParallel-v0", time_accel=10.0, base_step=0.1, clock=None, **same but step_dt)``:
the same world stepped by :class:`rmm_envs.wrappers.NonBlockingStepping`: each ``step(a)``
advances the world by ``elapsed * time_accel + base_step`` seconds under the *previous* action
and then stores ``a`` for the next interval (the first interval is the driver's).

## Rendering

``render_mode="rgb_array"``: a 512x512 top-down frame of the window ``[-15, 15]^2`` m:
the generation arena's outline, obstacles red, goal green (with a ring), rays grey, the vehicle
blue (driver) or orange (guardian).
``"human"`` shows the same frames with pygame; it is offered (listed in ``metadata``) only when the
optional extra ``rmm-envs[human]`` is installed.
"""

from __future__ import annotations

import importlib.util
import math
from collections.abc import Callable

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox
from rmm_envs.catalog import system
from rmm_envs.clocks import Clock, make_clock
from rmm_envs.envs import _render
from rmm_envs.envs.base import check_arguments, finite, whole
from rmm_envs.envs.guarded import GuardedEnv, Motion, parallel_twin
from rmm_envs.systems.dubins4d.dataset_hooks import Dubins4DDatasetHooks
from rmm_envs.systems.dubins4d.driver import CLFDriver, DriverParams
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.dubins4d.plant import plant_model
from rmm_envs.systems.dubins4d.scene import Dubins4DScene, observation, observation_layout
from rmm_envs.systems.dubins4d.starts import HALF as _HALF
from rmm_envs.systems.dubins4d.starts import STARTS, Dubins4DStarts
from rmm_envs.systems.dubins4d.step import advance as advance_batch
from rmm_envs.systems.dubins4d.step import nominal_controls

__all__ = ["Dubins4DGuardedEnv", "Dubins4DScene", "observation", "observation_layout", "plant_model"]

from rmm_envs.systems.dubins4d.dynamics import CONTROLS, DYNAMICS_NAME  # noqa: E402  (the action fields of u = (u1, u2); owned by the system)


class Dubins4DGuardedEnv(Dubins4DStarts, Dubins4DDatasetHooks, GuardedEnv):
    """Blocking Dubins4D parallel-autonomy env; see the module docstring for the full spec."""

    # "human" is offered only where its optional dependency (pygame) is installed
    metadata = {
        "render_modes": ["rgb_array"] + (["human"] if importlib.util.find_spec("pygame") else []),
        "render_fps": 15,
    }
    reset_options: tuple[str, ...] = ("state", "goal", "obstacles")
    #: ``None``: contacts with the circles of ``_circles``; a subclass on another world sets a
    #: function ``paths -> first obstacle contacts`` (see :func:`~rmm_envs.systems.dubins4d.step.advance`)
    _obstacle_contact: Callable[[np.ndarray], np.ndarray] | None = None
    #: a rate disturbance moves the car's position (the HJ model's ``|d_x|, |d_y| <= d_max``)
    disturbance_rates = {"x": 0, "y": 1}

    def disturbance_parameters(self) -> dict[str, float]:
        """What a ``mismatch`` scales: the turn-rate and acceleration gains and the top speed."""
        return {"turn_gain": 1.0, "accel_gain": 1.0, "v_max": float(self.dynamics.v_max)}

    def __init__(
        self,
        step_dt: float = 0.1,
        n_rays: int = 12,
        ray_length: float = 10.0,
        max_episode_sim_time: float = 100.0,
        n_obstacles: int = 5,
        obstacle_min_rad: float = 2.0,
        obstacle_max_rad: float = 5.0,
        goal_min_rad: float = 0.1,
        goal_max_rad: float = 1.0,
        n_path_points: int = 16,
        driver_params: DriverParams | dict | None = None,
        clock: Clock | str | None = None,
        render_mode: str | None = None,
        driver_solver: str = "closed_form",
        starts: str = "any",
        disturbances=None,
    ) -> None:
        # Every bound is finite: an infinite episode length, ray length or radius would silently
        # disable what it configures (no timeout, rays that never end, a goal covering everything).
        check_arguments(
            [
                (finite(step_dt) and step_dt > 0, "step_dt", step_dt, "a finite number > 0"),
                (whole(n_rays) and n_rays >= 1, "n_rays", n_rays, "an integer >= 1"),
                (finite(ray_length) and ray_length > 0, "ray_length", ray_length, "a finite number > 0"),
                (
                    finite(max_episode_sim_time) and max_episode_sim_time > 0,
                    "max_episode_sim_time",
                    max_episode_sim_time,
                    "a finite number of seconds > 0 (episodes need a time limit)",
                ),
                (whole(n_obstacles) and n_obstacles >= 0, "n_obstacles", n_obstacles, "an integer >= 0"),
                (
                    finite(obstacle_min_rad) and finite(obstacle_max_rad) and 0 < obstacle_min_rad <= obstacle_max_rad,
                    "obstacle radii",
                    (obstacle_min_rad, obstacle_max_rad),
                    "finite with 0 < min <= max",
                ),
                (
                    finite(goal_min_rad) and finite(goal_max_rad) and 0 < goal_min_rad <= goal_max_rad,
                    "goal radii",
                    (goal_min_rad, goal_max_rad),
                    "finite with 0 < min <= max",
                ),
                (whole(n_path_points) and n_path_points >= 2, "n_path_points", n_path_points, "an integer >= 2"),
                self.check_render_mode(render_mode),
                (starts in STARTS, "starts", starts, f"one of {', '.join(map(repr, STARTS))}"),
            ]
        )
        self.starts = starts
        self.step_dt = float(step_dt)
        self.n_rays = int(n_rays)
        self.ray_length = float(ray_length)
        self.max_episode_sim_time = float(max_episode_sim_time)
        self.n_obstacles = int(n_obstacles)
        self.obstacle_rad = (float(obstacle_min_rad), float(obstacle_max_rad))
        self.goal_rad = (float(goal_min_rad), float(goal_max_rad))
        self.n_path_points = int(n_path_points)
        self._step_times = np.linspace(0.0, self.step_dt, self.n_path_points)
        self.render_mode = render_mode
        self.dynamics = Dubins4D()
        if isinstance(driver_params, dict):
            try:
                driver_params = DriverParams(**driver_params)
            except TypeError as e:
                raise ValueError(f"driver_params: {e}; expected keys of DriverParams") from None
        s = self.dynamics
        self.driver = CLFDriver(
            (s.u1_min, s.u1_max),
            (s.u2_min, s.u2_max),
            (s.v_min, s.v_max),
            driver_params or DriverParams(),
            solver=driver_solver,
        )
        self.clock = make_clock(clock)
        self.action_space = GuardianActionSpace.for_dynamics(
            s, CONTROLS, safe_default=system("Dubins4D").make_safe_default(), dynamics_name=DYNAMICS_NAME
        )
        low = np.array([0.0, -np.inf, -np.inf, -np.pi, s.v_min] + [0.0] * self.n_rays, dtype=np.float32)
        high = np.array([np.inf, np.inf, np.inf, np.pi, s.v_max] + [self.ray_length] * self.n_rays, dtype=np.float32)
        self.observation_space = ObservationBox(low, high, observation_layout(self.n_rays))
        self.set_disturbances(disturbances)

        self.scene: Dubins4DScene | None = None
        self._state = np.zeros(4)
        self._last_active = False

    def begin(self, options: dict) -> np.ndarray:
        obstacles, state, goal = self.generate_start(self.np_random, options)
        if self.starts == "avoidable":
            obstacles, state, goal = self._avoidable_start(obstacles, state, goal, options)
        self._start_episode(obstacles, state, goal)
        return self._state

    def begin_plant(self, parameters: dict[str, float] | None) -> None:
        self._plant, self._gains = plant_model(self.dynamics, parameters)

    def _start_episode(self, obstacles: np.ndarray, state: np.ndarray, goal: np.ndarray) -> None:
        self.scene = Dubins4DScene(obstacles, goal, self.dynamics, self.n_rays, self.ray_length)
        self._circles = np.vstack([self.scene.obstacles, self.scene.goal[None, :]])
        self._state = state
        self.driver.reset()  # no warm start from an earlier episode: results depend on the seed only

    # ------------------------------------------------------------------ stepping
    def observe(self) -> np.ndarray:
        assert self.scene is not None  # set by reset, before any observation
        return self.sensed(self.scene.observe(self._state[None, :], self._sim_time)[0], self._sim_time)

    def advance(self, duration: float, active: bool, control) -> Motion:
        """The closed-form path under one held control (``(u1, u2)``), cut at its first contact
        with an obstacle or the goal (see the module docstring)."""
        if duration == self.step_dt:
            times = self._step_times
        else:
            times = np.linspace(0.0, float(duration), self.n_path_points)
        controls = np.zeros((1, 2)) if control is None else np.asarray(control, dtype=float).reshape(1, 2)
        act, plant, drift, applied = np.array([active]), self.dynamics, None, None
        if self.moves_plant:  # the actuators' control, the plant's gains, the drift
            applied = self.actuated(controls[0] if active else self._nominal, self._sim_time)
            act, plant, controls = np.array([True]), self._plant, (applied * self._gains)[None, :]
            rate = self.drift(self._sim_time, 4)
            drift = None if rate is None else rate[None, :]
        nxt, u, hit_obst, hit_goal = advance_batch(
            plant,
            self._nominal[None, :],
            self._state[None, :],
            self._circles[None],
            act,
            controls,
            times,
            self._obstacle_contact,
            drift,
        )
        hit_obst, hit_goal = float(hit_obst[0]), float(hit_goal[0])
        self._state = nxt[0]
        outcome = None
        if math.isfinite(hit_obst) and hit_obst <= hit_goal:
            outcome = "collision"
        elif math.isfinite(hit_goal):
            outcome = "goal"
        return Motion(outcome, u[0] if applied is None else applied, self._state)

    def final_speed(self) -> float:
        return float(self._state[3])

    def driver_control(self) -> np.ndarray:
        return nominal_controls(self.driver, self._state[None, :], self._circles[None])[0]

    # ------------------------------------------------------------------ accessors
    def privileged(self) -> dict:
        """The true state and the world's geometry (copies).  **Privileged**: for guardians
        that declare they need it (CBF, HJ) and for analysis, never for local-observation ones."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        out = {
            "state": self._state.copy(),
            "obstacles": self.scene.obstacles.copy(),
            "goal": self.scene.goal.copy(),
            "sim_time": self._sim_time,
        }
        if self.disturbances:  # what the world does to the car, for a guardian that models it (hj)
            out["disturbances"] = [str(d) for d in self.disturbances]
        return out

    @property
    def true_state(self) -> np.ndarray:
        return self._state.copy()

    @property
    def sim_time(self) -> float:
        return self._sim_time

    # ------------------------------------------------------------------ rendering
    def render_frame(self, size: int = 512) -> np.ndarray:
        """The ``rgb_array`` frame described under "Rendering" above."""
        if self.scene is None:
            return _render.Canvas(size, -15, 15, -15, 15).img
        return _render.dubins4d_frame(self.scene, self._state, self._last_active, _HALF, size)


parallel_env = parallel_twin(Dubins4DGuardedEnv, "Dubins4DParallel-v0")
