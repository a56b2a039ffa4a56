"""Dubins4D among circles: a reckless driver, a guardian that may take over, and lidar.

``Dubins4DCircles-v0`` (blocking, fixed step) and ``Dubins4DParallel-v0`` (non-blocking: the
guardian's thinking time passes in the world).  This is the paper's parallel-autonomy case study
(Sec. IV-A, Table I), rebuilt on Gymnasium.

## Description

A car-like vehicle (:class:`rmm_envs.systems.Dubins4D`) drives toward a circular goal among
``n_obstacles`` circular obstacles.  A built-in "reckless driver" (:class:`rmm_envs.driver.
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

## Info

Every step: ``sim_time``; ``state`` (the true state: **privileged**, for analysis and for
guardians that declare they use it); ``active`` and ``control`` (what was applied during the
step and whether the guardian applied it).  On the last step also ``outcome`` (``"goal"``, ``"collision"``
or ``"timeout"``) and ``episode`` (the statistics of the paper's Table I: ``n_env_steps``,
``n_active_ctrl_env_steps``, ``active_ctrl_sim_time``, ``cum_sim_time``, ``cum_compute_time``,
``avg_compute_time``, ``cum_reward``, ``final_speed``, ``outcome``).

Privileged information is also available through :meth:`Dubins4DCirclesEnv.privileged`.

## Arguments

``gym.make("Dubins4DCircles-v0", step_dt=0.1, n_rays=12, ray_length=10.0,
max_episode_sim_time=100.0, n_obstacles=5, obstacle_min_rad=2.0, obstacle_max_rad=5.0,
goal_min_rad=0.1, goal_max_rad=1.0, n_path_points=16, driver_params=None, clock=None,
render_mode=None, driver_solver="closed_form")``.  ``clock`` ("wall", "cpu", "fixed:MS" or a
:class:`rmm_envs.clocks.Clock`) only measures the agent's compute time for the statistics in the
blocking env.  ``driver_solver``: how the driver's QP is solved, ``"closed_form"`` (exact, the
default) or ``"osqp"`` (the earlier solver, kept for checking; equal to about 1e-7).

``gym.make_vec("Dubins4DCircles-v0", num_envs=N, vectorization_mode="vector_entry_point")``:
:class:`rmm_envs.envs.dubins4d_vector.Dubins4DCirclesVectorEnv`, ``N`` copies of this env
computed as arrays (sub-env ``i`` after ``reset(seed=s)`` is this env after ``reset(seed=s +
i)``, bit for bit).

``gym.make("Dubins4DParallel-v0", time_accel=10.0, base_step=0.1, clock=None, **same)``:
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
from typing import Any

import gymnasium as gym
import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox, ObservationLayout, parse
from rmm_envs.clocks import Clock, make_clock
from rmm_envs.driver import CLFDriver, DriverParams
from rmm_envs.envs import _render
from rmm_envs.envs.dubins4d_step import advance
from rmm_envs.risk.protocol import SceneBase
from rmm_envs.systems.dubins4d import Dubins4D, wrap_angle
from rmm_envs.worlds.circles import (
    CircleWorld,
    as_circles,
    paths_hit_circles,
    points_in_circles,
    ray_cast,
)

__all__ = ["Dubins4DCirclesEnv", "Dubins4DScene", "parse_guardian_action"]

OBS_DIM = 17
CONTROLS = ("turnrate_ctrl", "accel_ctrl")  # the action fields of u = (u1, u2)


def observation_layout(n_rays: int = 12) -> ObservationLayout:
    """The named slices of the observation table above; ray ``i`` points ``2 pi i / n_rays`` left of the heading."""
    return ObservationLayout.of(("time", 1), ("goal_offset", 2), ("heading", 1), ("speed", 1), ("rays", n_rays),
                                ray_angles=[2.0 * math.pi * i / n_rays for i in range(n_rays)])
_HALF = 10.0  # arena half width (generation only)


def observation(states: np.ndarray, sim_time, goals: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """The observation table above for ``N`` states ``(N, 4)``: ``sim_time`` scalar or ``(N,)``,
    goal centres ``(N, 2)`` (or ``(1, 2)`` for all), ray lengths ``(N, n_rays)``; float32."""
    obs = np.empty((states.shape[0], 5 + rays.shape[1]), dtype=np.float32)
    obs[:, 0] = sim_time
    obs[:, 1] = goals[:, 0] - states[:, 0]
    obs[:, 2] = goals[:, 1] - states[:, 1]
    obs[:, 3] = wrap_angle(states[:, 2])
    obs[:, 4] = states[:, 3]
    obs[:, 5:] = rays
    return obs


class Dubins4DScene(SceneBase):
    """A Dubins4D vehicle among fixed circles: what the risk estimator needs of the env.

    Implements :class:`rmm_envs.risk.System`: control bounds and sampling, batched exact
    propagation, path failure (any point or segment touching an obstacle) and the 17-dim
    observation.  The environment uses the very same object, so labels and the env agree by
    construction.
    """

    def __init__(
        self,
        obstacles: np.ndarray,
        goal: np.ndarray,
        system: Dubins4D | None = None,
        n_rays: int = 12,
        ray_length: float = 10.0,
    ) -> None:
        self.system = system or Dubins4D()
        self.world = CircleWorld(obstacles, goal)
        self.n_rays = int(n_rays)
        self.ray_length = float(ray_length)
        self.state_dim = 4
        self.control_dim = 2
        self.obs_dim = 5 + self.n_rays

    @property
    def obstacles(self) -> np.ndarray:
        return self.world.obstacles

    @property
    def goal(self) -> np.ndarray:
        return self.world.goal

    def state_failed(self, states: np.ndarray) -> np.ndarray:
        return points_in_circles(np.asarray(states)[:, :2], self.world.obstacles)

    def path_failed(self, paths: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: a path ``(N, S, 4)`` touches an obstacle at a point or segment."""
        return paths_hit_circles(paths, self.world.obstacles)

    def observe(self, states: np.ndarray, sim_time=0.0) -> np.ndarray:
        """``(N, 17)`` float32 observations for states ``(N, 4)`` at ``sim_time`` (scalar or ``(N,)``)."""
        states = np.asarray(states, dtype=float)
        rays = ray_cast(states[:, :2], states[:, 2], self.world.obstacles, self.n_rays, self.ray_length)
        return observation(states, sim_time, self.world.goal[None, :2], rays)

    def leaf_estimate(self, states: np.ndarray) -> np.ndarray:
        """pyrmm's Dubins4D stopping-distance leaf heuristic (docs/original-code.md, item 24), ``(N,)``.

        Braking at 0.5 m/s^2 from speed ``v`` covers ``v^2`` m; the risk is that distance over
        the forward ray, capped at 1 (1 when the ray reads 0).  Speeds are never negative here,
        and ``v = 0`` gives 0 (the original asserted on it).
        """
        states = np.asarray(states, dtype=float)
        v = np.clip(states[:, 3], self.system.v_min, self.system.v_max)
        a = abs(self.system.u2_min)
        d_stop = v * v / (2.0 * a)
        fwd = ray_cast(states[:, :2], states[:, 2], self.world.obstacles, 1, self.ray_length)[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            risk = np.where(fwd <= 0, 1.0, np.minimum(d_stop / fwd, 1.0))
        return np.where(v <= 0, np.where(fwd <= 0, 1.0, 0.0), risk)


def parse_guardian_action(action, space: GuardianActionSpace) -> tuple[bool, np.ndarray]:
    """Validate a guardian action; return ``(active, (u1, u2) clipped)`` (:func:`rmm_envs.autonomy.parse`)."""
    return parse(action, space)


def _finite(x) -> bool:
    """A real, finite number (not a bool, string or array)."""
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool) and math.isfinite(x)


def _whole(x) -> bool:
    """An integer value (``3`` or ``3.0``), finite."""
    return _finite(x) and float(x) == int(x)


def _vector(value, n: int, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"option {name!r} must be {n} finite numbers, got {value!r}")
    return arr


class Dubins4DCirclesEnv(gym.Env):
    """Blocking Dubins4D parallel-autonomy env; see the module docstring for the full spec."""

    # "human" is offered only where its optional dependency (pygame) is installed
    metadata = {
        "render_modes": ["rgb_array"] + (["human"] if importlib.util.find_spec("pygame") else []),
        "render_fps": 15,
    }

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
    ) -> None:
        # Every bound is finite: an infinite episode length, ray length or radius would silently
        # disable what it configures (no timeout, rays that never end, a goal covering everything).
        checks = [
            (_finite(step_dt) and step_dt > 0, "step_dt", step_dt, "a finite number > 0"),
            (_whole(n_rays) and n_rays >= 1, "n_rays", n_rays, "an integer >= 1"),
            (_finite(ray_length) and ray_length > 0, "ray_length", ray_length, "a finite number > 0"),
            (_finite(max_episode_sim_time) and max_episode_sim_time > 0, "max_episode_sim_time", max_episode_sim_time,
             "a finite number of seconds > 0 (episodes need a time limit)"),
            (_whole(n_obstacles) and n_obstacles >= 0, "n_obstacles", n_obstacles, "an integer >= 0"),
            (_finite(obstacle_min_rad) and _finite(obstacle_max_rad) and 0 < obstacle_min_rad <= obstacle_max_rad,
             "obstacle radii", (obstacle_min_rad, obstacle_max_rad), "finite with 0 < min <= max"),
            (_finite(goal_min_rad) and _finite(goal_max_rad) and 0 < goal_min_rad <= goal_max_rad,
             "goal radii", (goal_min_rad, goal_max_rad), "finite with 0 < min <= max"),
            (_whole(n_path_points) and n_path_points >= 2, "n_path_points", n_path_points, "an integer >= 2"),
            (render_mode is None or render_mode in self.metadata["render_modes"], "render_mode", render_mode, f"one of {self.metadata['render_modes']}"),
        ]
        for ok, name, value, expected in checks:
            if not ok:
                raise ValueError(f"{name} must be {expected}, got {value!r}")
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
        self.system = Dubins4D()
        if isinstance(driver_params, dict):
            try:
                driver_params = DriverParams(**driver_params)
            except TypeError as e:
                raise ValueError(f"driver_params: {e}; expected keys of DriverParams") from None
        self.driver = CLFDriver(
            (self.system.u1_min, self.system.u1_max),
            (self.system.u2_min, self.system.u2_max),
            (self.system.v_min, self.system.v_max),
            driver_params or DriverParams(),
            solver=driver_solver,
        )
        self.clock = make_clock(clock)

        s = self.system
        self.action_space = GuardianActionSpace.for_system(s, CONTROLS)
        low = np.array([0.0, -np.inf, -np.inf, -np.pi, s.v_min] + [0.0] * self.n_rays, dtype=np.float32)
        high = np.array([np.inf, np.inf, np.inf, np.pi, s.v_max] + [self.ray_length] * self.n_rays, dtype=np.float32)
        self.observation_space = ObservationBox(low, high, observation_layout(self.n_rays))

        self.scene: Dubins4DScene | None = None
        self._state = np.zeros(4)
        self._window = None
        self._last_active = False

    # ------------------------------------------------------------------ generation
    # The rules a start (state, goal, obstacles) obeys, whether generated or given:
    #   R1 the vehicle's position is outside every obstacle (boundary counts as inside);
    #   R2 the vehicle's position is outside the goal (boundary counts as inside);
    #   R3 the goal is not entirely inside one obstacle.
    # Generated parts are rejection-sampled until they obey them against every given part.
    _MAX_DRAWS = 100_000
    _MAX_OBSTACLE_DRAWS = 1_000  # a state at the arena's centre is left free by ~1 draw in 8

    @staticmethod
    def _goal_inside_obstacle(goal: np.ndarray, obstacles: np.ndarray) -> int | None:
        """Index of an obstacle that contains the whole goal disc (R3), or ``None``."""
        if not obstacles.shape[0]:
            return None
        inside = np.hypot(*(goal[None, :2] - obstacles[:, :2]).T) + goal[2] < obstacles[:, 2]
        return int(np.argmax(inside)) if inside.any() else None

    @staticmethod
    def _in_goal(state: np.ndarray, goal: np.ndarray) -> bool:
        return bool(np.hypot(*(state[:2] - goal[:2])) <= goal[2])

    def _generate_obstacles(self, rng: np.random.Generator, state: np.ndarray | None, goal: np.ndarray | None) -> np.ndarray:
        for _ in range(self._MAX_OBSTACLE_DRAWS):
            obstacles = CircleWorld.generate(rng, self.n_obstacles, *self.obstacle_rad, half_width=_HALF)
            if state is not None and points_in_circles(state[None, :2], obstacles)[0]:
                continue
            if goal is not None and self._goal_inside_obstacle(goal, obstacles) is not None:
                continue
            return obstacles
        given = " and ".join(f"option {k!r} {v[:2 if k == 'state' else 3].tolist()}" for k, v in (("state", state), ("goal", goal)) if v is not None)
        raise ValueError(f"could not generate {self.n_obstacles} obstacles clear of {given} in {self._MAX_OBSTACLE_DRAWS} draws; "
                         "give 'obstacles' explicitly too")

    def _generate_state(self, rng: np.random.Generator, obstacles: np.ndarray, goal: np.ndarray | None = None,
                        given: tuple[str, ...] = ()) -> np.ndarray:
        if goal is not None:
            corners = np.array([[-_HALF, -_HALF], [-_HALF, _HALF], [_HALF, -_HALF], [_HALF, _HALF]])
            if np.all(np.hypot(*(corners - goal[:2]).T) <= goal[2]):  # a disc is convex: it holds the square
                raise ValueError(f"option 'goal' {goal.tolist()} covers the whole arena [-{_HALF}, {_HALF}]^2 where "
                                 "initial states are drawn, so no start outside it exists; give a smaller goal")
        for _ in range(self._MAX_DRAWS):
            st = np.array(
                [rng.uniform(-_HALF, _HALF), rng.uniform(-_HALF, _HALF),
                 rng.uniform(-np.pi, np.pi), rng.uniform(self.system.v_min, self.system.v_max)]
            )
            if points_in_circles(st[None, :2], obstacles)[0]:
                continue
            if goal is not None and self._in_goal(st, goal):
                continue
            return st
        if given:
            raise ValueError(f"could not draw an initial state on the arena [-{_HALF}, {_HALF}]^2 outside "
                             f"{' and '.join(f'option {k!r}' for k in given)} in {self._MAX_DRAWS} draws: they leave "
                             "too little free space; give 'state' explicitly too")
        raise RuntimeError(f"could not find a collision-free initial state in {self._MAX_DRAWS} draws")

    def _generate_goal(self, rng: np.random.Generator, state: np.ndarray, obstacles: np.ndarray,
                       given: tuple[str, ...] = ()) -> np.ndarray:
        for _ in range(self._MAX_DRAWS):
            g = np.array([rng.uniform(-_HALF, _HALF), rng.uniform(-_HALF, _HALF), rng.uniform(*self.goal_rad)])
            if self._in_goal(state, g):
                continue
            if self._goal_inside_obstacle(g, obstacles) is not None:
                continue
            return g
        if given:
            raise ValueError(f"could not place a goal around {' and '.join(f'option {k!r}' for k in given)} "
                             f"in {self._MAX_DRAWS} draws; give 'goal' explicitly too")
        raise RuntimeError(f"could not place a goal in {self._MAX_DRAWS} draws")

    def _given_options(self, options: dict) -> dict:
        """Validate the given parts of a start on their own and against each other (R1-R3)."""
        given = {}
        if "obstacles" in options:
            given["obstacles"] = as_circles(options["obstacles"], "option 'obstacles'")
        if "state" in options:
            state = _vector(options["state"], 4, "state")
            if not (self.system.v_min <= state[3] <= self.system.v_max):
                raise ValueError(f"option 'state': speed must be in [{self.system.v_min}, {self.system.v_max}], got {state[3]}")
            state[2] = wrap_angle(state[2])
            given["state"] = state
        if "goal" in options:
            goal = _vector(options["goal"], 3, "goal")
            if goal[2] <= 0:
                raise ValueError(f"option 'goal': radius must be > 0, got {goal[2]}")
            given["goal"] = goal
        obstacles, state, goal = given.get("obstacles"), given.get("state"), given.get("goal")
        if state is not None and obstacles is not None:
            hits = [points_in_circles(state[None, :2], o[None, :])[0] for o in obstacles]
            if any(hits):
                k = hits.index(True)
                raise ValueError(f"option 'state': position {state[:2].tolist()} is inside obstacle {k} "
                                 f"{obstacles[k].tolist()} of option 'obstacles'")
        if goal is not None and obstacles is not None:
            k = self._goal_inside_obstacle(goal, obstacles)
            if k is not None:
                raise ValueError(f"option 'goal' {goal.tolist()} lies entirely inside obstacle {k} {obstacles[k].tolist()} "
                                 "of option 'obstacles', so it can never be reached (generation never places a goal there)")
        if state is not None and goal is not None and self._in_goal(state, goal):
            raise ValueError(f"option 'state': position {state[:2].tolist()} is already inside option 'goal' {goal.tolist()}")
        return given

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obstacles, state, goal = self.generate_start(self.np_random, options)
        self._start_episode(obstacles, state, goal)
        obs = self._observe()
        info = {"sim_time": 0.0, "state": self._state.copy()}
        if self.render_mode == "human":
            self.render()
        self.clock.start()
        return obs, info

    def generate_start(self, rng: np.random.Generator, options: dict[str, Any] | None = None):
        """``(obstacles, state, goal)`` of a new episode drawn from ``rng`` around the reset
        ``options`` (validated); what :meth:`reset` does (the vector env calls it per sub-env)."""
        options = dict(options or {})
        unknown = set(options) - {"state", "goal", "obstacles"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; expected any of 'state', 'goal', 'obstacles'")
        given = self._given_options(options)
        # Generation order (obstacles, state, goal) and its draws are those of a reset without
        # options; each generated part is redrawn until it obeys R1-R3 against the given parts.
        obstacles = given.get("obstacles")
        if obstacles is None:
            obstacles = self._generate_obstacles(rng, given.get("state"), given.get("goal"))
        state = given.get("state")
        if state is None:
            state = self._generate_state(rng, obstacles, given.get("goal"), tuple(k for k in ("obstacles", "goal") if k in given))
        goal = given.get("goal")
        if goal is None:
            goal = self._generate_goal(rng, state, obstacles, tuple(k for k in ("state", "obstacles") if k in given))
        return obstacles, state, goal

    def _start_episode(self, obstacles: np.ndarray, state: np.ndarray, goal: np.ndarray) -> None:
        self.scene = Dubins4DScene(obstacles, goal, self.system, self.n_rays, self.ray_length)
        self._circles = np.vstack([self.scene.obstacles, self.scene.goal[None, :]])
        self._state = state
        self._sim_time = 0.0
        self._n_steps = 0
        self._n_active_steps = 0
        self._active_sim_time = 0.0
        self._cum_compute = 0.0
        self._cum_reward = 0.0
        self._done = False
        self._last_active = False
        self._last_control = np.zeros(2)
        self.driver.reset()  # no warm start from an earlier episode: results depend on the seed only

    # ------------------------------------------------------------------ stepping
    def _observe(self) -> np.ndarray:
        return self.scene.observe(self._state[None, :], self._sim_time)[0]

    def step(self, action):
        compute = self.clock.elapsed()
        active, ctrl = parse_guardian_action(action, self.action_space)
        out = self.simulate(self.step_dt, active, ctrl, compute)
        self.clock.start()
        return out

    def simulate(self, duration: float, active: bool, control, compute_time: float = 0.0):
        """Advance the world by ``duration`` seconds under one held control.

        ``active=False`` lets the driver choose the control at the start of the interval;
        otherwise ``control = (u1, u2)`` (already validated) is applied.  ``compute_time`` is the
        agent's thinking time attributed to this step (statistics only).  Used by :meth:`step`
        and by the non-blocking wrapper; returns the usual 5-tuple.
        """
        if self.scene is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("the episode has ended; call reset() before stepping again")
        if not (duration >= 0 and math.isfinite(duration)):
            raise ValueError(f"duration must be a finite number >= 0, got {duration}")
        if duration == self.step_dt:
            times = self._step_times
        else:
            times = np.linspace(0.0, float(duration), self.n_path_points)
        nxt, u, hit_obst, hit_goal = advance(self.system, self.driver, self._state[None, :], self._circles[None],
                                             np.array([bool(active)]), np.zeros((1, 2)) if control is None else np.asarray(control, dtype=float).reshape(1, 2),
                                             times)
        hit_obst, hit_goal = float(hit_obst[0]), float(hit_goal[0])
        u = u[0]

        self._n_steps += 1
        if active:
            self._n_active_steps += 1
            self._active_sim_time += duration
        self._cum_compute += compute_time
        self._sim_time += duration
        self._state = nxt[0]
        self._last_active = bool(active)
        self._last_control = u

        outcome = None
        reward = 0.0
        if math.isfinite(hit_obst) and hit_obst <= hit_goal:
            outcome, reward = "collision", -1.0
        elif math.isfinite(hit_goal):
            outcome, reward = "goal", 1.0
        terminated = outcome is not None
        truncated = not terminated and self._sim_time >= self.max_episode_sim_time - 1e-9
        if truncated:
            outcome = "timeout"
        self._cum_reward += reward

        info = {
            "sim_time": self._sim_time,
            "state": self._state.copy(),
            "active": bool(active),
            "control": u.copy(),
        }
        if terminated or truncated:
            self._done = True
            info["outcome"] = outcome
            info["episode"] = self.episode_statistics(outcome)
        obs = self._observe()
        if self.render_mode == "human":
            self.render()
        return obs, reward, terminated, truncated, info

    def episode_statistics(self, outcome: str | None = None) -> dict:
        n = self._n_steps
        return {
            "outcome": outcome,
            "n_env_steps": n,
            "n_active_ctrl_env_steps": self._n_active_steps,
            "active_ctrl_sim_time": self._active_sim_time,
            "cum_sim_time": self._sim_time,
            "cum_compute_time": self._cum_compute,
            "avg_compute_time": self._cum_compute / n if n else 0.0,
            "cum_reward": self._cum_reward,
            "final_speed": float(self._state[3]),
        }

    # ------------------------------------------------------------------ accessors
    def privileged(self) -> dict:
        """The true state and the world's geometry (copies).  **Privileged**: for guardians
        that declare they need it (CBF, HJ) and for analysis, never for local-observation ones."""
        if self.scene is None:
            raise RuntimeError("call reset() first")
        return {
            "state": self._state.copy(),
            "obstacles": self.scene.obstacles.copy(),
            "goal": self.scene.goal.copy(),
            "sim_time": self._sim_time,
        }

    def risk_system(self) -> Dubins4DScene:
        """The :class:`rmm_envs.risk.System` of the current episode (for risk labelling)."""
        if self.scene is None:
            raise RuntimeError("call reset() first")
        return self.scene

    # ------------------------------------------------------------------ dataset hooks
    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` states uniform over the arena x [-pi, pi) x [0, 2], outside every obstacle
        (rejection sampling, as the original's datagen since 2022-09-13)."""
        if self.scene is None:
            raise RuntimeError("call reset() first")
        out = np.empty((0, 4))
        s = self.system
        while out.shape[0] < n:
            m = max(2 * (n - out.shape[0]), 16)
            cand = np.column_stack([
                rng.uniform(-_HALF, _HALF, m), rng.uniform(-_HALF, _HALF, m),
                rng.uniform(-np.pi, np.pi, m), rng.uniform(s.v_min, s.v_max, m),
            ])
            out = np.vstack([out, cand[~self.scene.state_failed(cand)]])
        return out[:n]

    def observe_states(self, states: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Observations of arbitrary states for a dataset.  The simulated-time feature is drawn
        uniformly over the episode range ``[0, max_episode_sim_time]``: the original left it 0
        in every training sample and met 0-100 s at run time (docs/original-code.md, item 8)."""
        t = rng.uniform(0.0, self.max_episode_sim_time, size=np.asarray(states).shape[0])
        return self.scene.observe(states, t)

    @property
    def true_state(self) -> np.ndarray:
        return self._state.copy()

    @property
    def sim_time(self) -> float:
        return self._sim_time

    # ------------------------------------------------------------------ rendering
    def _frame(self, size: int = 512) -> np.ndarray:
        cv = _render.Canvas(size, -15, 15, -15, 15)
        if self.scene is None:
            return cv.img
        for a, b in (((-_HALF, -_HALF), (_HALF, -_HALF)), ((_HALF, -_HALF), (_HALF, _HALF)),
                     ((_HALF, _HALF), (-_HALF, _HALF)), ((-_HALF, _HALF), (-_HALF, -_HALF))):
            cv.line(a[0], a[1], b[0], b[1], (225, 225, 225))  # the arena used for generation
        g = self.scene.goal
        cv.disc(g[0], g[1], g[2], _render.GREEN)
        cv.ring(g[0], g[1], g[2] + 0.25, _render.GREEN, 0.12)
        for ox, oy, r in self.scene.obstacles:
            cv.disc(ox, oy, r, _render.RED)
        x, y, th, v = self._state
        rays = ray_cast(self._state[None, :2], np.array([th]), self.scene.obstacles, self.n_rays, self.ray_length)[0]
        for i, d in enumerate(rays):
            a = th + 2 * np.pi * i / self.n_rays
            cv.line(x, y, x + d * np.cos(a), y + d * np.sin(a), _render.GREY)
        colour = _render.ORANGE if self._last_active else _render.BLUE
        cv.disc(x, y, 0.4, colour)
        cv.line(x, y, x + (0.5 + v) * np.cos(th), y + (0.5 + v) * np.sin(th), colour)
        return cv.img

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        frame = self._frame()
        if self.render_mode == "rgb_array":
            return frame
        try:
            import pygame
        except ImportError as e:  # pragma: no cover - optional extra
            raise gym.error.DependencyNotInstalled("render_mode='human' needs pygame: pip install rmm-envs[human]") from e
        if self._window is None:  # pragma: no cover - needs a display
            pygame.init()
            self._window = pygame.display.set_mode(frame.shape[:2])
        surf = pygame.surfarray.make_surface(frame.swapaxes(0, 1))  # pragma: no cover
        self._window.blit(surf, (0, 0))  # pragma: no cover
        pygame.event.pump()  # pragma: no cover
        pygame.display.flip()  # pragma: no cover
        return None

    def close(self):
        if self._window is not None:  # pragma: no cover
            import pygame

            pygame.display.quit()
            pygame.quit()
            self._window = None


def make_parallel_env(time_accel: float = 10.0, base_step: float = 0.1, clock=None, **kwargs):
    """Entry point of ``Dubins4DParallel-v0``: the blocking env under non-blocking stepping."""
    from rmm_envs.wrappers.nonblocking import NonBlockingStepping

    return NonBlockingStepping(Dubins4DCirclesEnv(**kwargs), time_accel=time_accel, base_step=base_step, clock=clock)
