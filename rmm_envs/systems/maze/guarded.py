"""The maze car under parallel autonomy: a reckless driver, a guardian that may take over.

``Dubins3DMazeGuarded-v0`` (blocking, fixed step) and ``Dubins3DMazeParallel-v0`` (non-blocking:
the guardian's thinking time passes in the world), the maze counterparts of
``Dubins4DGuarded-v0`` and ``Dubins4DParallel-v0`` with the same contract
(:mod:`rmm_envs.autonomy`), so the same guardians and ``rmm-bench --env`` run on both systems.

## Description

The constant-speed car of ``Dubins3DMaze-v0`` (:class:`rmm_envs.systems.maze.dynamics.Dubins3D`: 10 px/s,
minimum turning radius 50 px, so ``|u| <= 0.2`` rad/s) in a seeded perfect maze (10 x 10 cells
of 125 px, walls 12.5 px thick; :mod:`rmm_envs.systems.maze.mazes`) must reach a goal disc in the
centre of a goal cell.  A built-in reckless driver (:class:`rmm_envs.systems.maze.driver.PursuitDriver`)
follows the maze's cell path to the goal by pure pursuit with a long look-ahead, cutting
corners and ignoring the walls: alone it collides in 46% of the episodes (256 episodes of
``rmm-bench`` seed 0, fixed 1 ms clock) and reaches the goal in the rest.  The agent is a
*guardian*: at every step it decides whether to take over the turn rate.

**Units** are the paper's pixels (``length_unit = "px"``).  For reading them physically the env
states a nominal scale, ``metres_per_unit = 0.01`` (1 px = 1 cm: a small indoor robot at
0.1 m/s with a 0.5 m turning radius in 1.25 m cells); nothing in the env depends on it, and
``rmm-envs demo`` prints speeds in m/s at this scale with px/s in brackets.

## Dynamics

``x' = 10 cos(psi), y' = 10 sin(psi), psi' = u``, integrated exactly for the step's held turn
rate; each step is checked as a path of ``n_path_points`` (8) points and the segments between
them.  The speed is constant: the car cannot stop.

## Action space

``Dict(active_ctrl=Discrete(2), turnrate_ctrl=Box(-0.2, 0.2, (1,)))``, a
:class:`rmm_envs.autonomy.GuardianActionSpace` built from the system's bounds.
``active_ctrl = 0``: the driver steers this step; ``1``: ``turnrate_ctrl`` is applied, clipped
to the bounds.  NaN/inf, a wrong shape or type, a missing or unknown field, or an
``active_ctrl`` other than 0/1 raise ``ValueError`` naming the field.  The space's safe default
(``space.safe_default``, what the ``brakes`` guardian applies) is :class:`TurnFromNearerWall`:
the maximum turn away from the nearer wall.

## Observation space

``Box(11,)`` float32, an :class:`rmm_envs.autonomy.ObservationBox` with a named layout:

| index | field         | observation                                              | min  | max |
|-------|---------------|----------------------------------------------------------|------|-----|
| 0-7   | ``rays``      | distances along rays at ``psi + k pi / 4``, px            | 0    | inf |
| 8-9   | ``goal_offset``| goal centre minus position, px (world frame)             | -inf | inf |
| 10    | ``heading``   | ``psi``, rad, wrapped to ``[-pi, pi)``                     | -pi  | pi  |

The rays are exactly those of ``Dubins3DMaze-v0`` (ray ``k`` at ``k pi / 4`` counter-clockwise
from the heading, to the first wall surface, 0 from inside a wall), so the risk model trained
there reads them unchanged; the goal offset and heading are what a guardian needs to weigh
safety against progress.

## Rewards and episode end

``+1`` on reaching the goal (a path point or segment within ``goal_radius`` of the goal
centre), ``-1`` on touching a wall (exactly, as ``Dubins3DMaze-v0``), else 0; a step that does
both is a collision.  ``terminated`` on either; ``truncated`` when simulated time reaches
``max_episode_sim_time`` (300 s: 2.5 times the longest drive from start to goal).  The state
after a collision step is the end of that step's path.

## Starting state

A maze from the seed; a start cell uniform over the maze's cells; a goal cell uniform over the
cells ``goal_cells = (4, 8)`` passages away (inclusive; a perfect maze always has cells at
every distance up to its eccentricity); the car at the start cell's centre plus a uniform
offset of up to ``start_jitter`` (15 px) per axis, heading toward the next cell of its path
plus ``U(-heading_noise, heading_noise)`` (``pi / 4``).  ``reset(seed=..., options={"maze":
Maze or dict of generate_maze arguments, "state": [x, y, psi], "goal_cell": int})`` sets any of
them: with ``"state"`` the start cell is the cell whose centre is nearest; a state inside a
wall or outside the maze's cells, a goal cell out of range or equal to the start cell, no cell
at the goal distance, an unknown key or a malformed value raise ``ValueError``.

## Risk labelling

The :class:`rmm_envs.risk.LabelledEnv` hooks: ``risk_scene()`` is the episode's
:class:`rmm_envs.scenes.MazeScene` (rays only, as ``Dubins3DMaze-v0``); ``sample_states`` draws
poses uniform over the image clear of the walls; ``observe_states(states)`` is this env's full
observation of those poses (no random feature).

## Info

Every step: ``sim_time``, ``state`` (the true pose, **privileged**), ``active`` and ``control``
(what was applied during the step), ``cost`` (1.0 on the step that touches a wall, else 0.0)
and ``nominal_control`` (also on ``reset``): the driver's turn rate at the pose the returned
observation shows, exactly what it applies if the guardian leaves it the next interval.  On
the last step also ``outcome`` (``"goal"``, ``"collision"`` or ``"timeout"``) and
``episode_stats``, the same statistics as Dubins4D's (``n_env_steps``,
``n_active_ctrl_env_steps``, ``active_ctrl_sim_time``, ``cum_sim_time``, ``cum_compute_time``,
``avg_compute_time``, ``cum_reward``, ``cum_cost``, ``final_speed`` (the constant speed),
``outcome``).  :meth:`Dubins3DMazeGuardedEnv.privileged` returns the pose, the maze,
the goal ``[x, y, r]``, the car's speed (px/s), the simulated time and any ``disturbances``.

## Arguments

``gym.make("Dubins3DMazeGuarded-v0", step_dt=0.1, n_path_points=8, max_episode_sim_time=300.0,
goal_cells=(4, 8), goal_radius=30.0, start_jitter=15.0, heading_noise=pi/4, lookahead=190.0,
driver_gain=1.0, maze_rows=10, maze_cols=10, speed=10.0, r_min=50.0, clock=None,
render_mode=None, disturbances=None)``.  ``disturbances``: sensor noise (the rays, the goal
offset, the heading), actuation error on the turn rate, a drift of the position (``x``, ``y``, px/s),
impulses, or a plant whose ``speed`` and ``turn_gain`` differ from the model's
(:mod:`rmm_envs.disturbances`; off by default; no ray dropouts: the rays have no maximum range).
``step_dt`` 0.1 s as Dubins4D: the blocking env re-decides every 1 px of
travel.  ``goal_radius`` 30 px: half a corridor, so the driver cannot miss it when it arrives.
``lookahead`` (px) and ``driver_gain`` (1/s): the driver's (:mod:`rmm_envs.systems.maze.driver`, where
the collision rate against the look-ahead is measured).  A 10 x 10 maze holds every drive (the
goal is at most 8 cells away) and resets ~8x faster than the paper's 20 x 20 (the ``Maze``
spatial index); the rays are local either way.  ``clock`` only measures the agent's compute
time in the blocking env.

``gym.make("Dubins3DMazeParallel-v0", time_accel=10.0, base_step=0.1, clock=None, **same but step_dt)``:
the same world under :class:`rmm_envs.wrappers.NonBlockingStepping` (each ``step(a)`` advances
the world by ``elapsed * time_accel + base_step`` seconds under the previous action, then
stores ``a``; the first interval is the driver's), with ``Dubins4DParallel-v0``'s defaults.

## Rendering

``render_mode="rgb_array"``: a 512 x 512 frame of the maze (walls black), the goal (green), the
driver's path (grey) and the car (blue: driver, orange: guardian).
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox
from rmm_envs.catalog import system
from rmm_envs.clocks import Clock, make_clock
from rmm_envs.envs import _render
from rmm_envs.envs.base import check_arguments, finite, whole
from rmm_envs.envs.guarded import GuardedEnv, Motion, parallel_twin
from rmm_envs.systems.dubins4d.dynamics import SERIES_COEFFICIENTS
from rmm_envs.systems.maze.driver import PursuitDriver
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.env import Dubins3DMazeEnv
from rmm_envs.systems.maze.maze_kernels import dubins_path, maze_path_hit, maze_rays, path_reaches_disc
from rmm_envs.systems.maze.observation import N_RAYS, TurnFromNearerWall, observation_layout
from rmm_envs.systems.maze.scene import MazeScene
from rmm_envs.systems.maze.starts import MazeStarts
from rmm_envs.worlds.bounds import MAX_MAZE_SIDE

__all__ = ["CONTROLS", "Dubins3DMazeGuardedEnv", "TurnFromNearerWall", "parallel_env", "observation_layout"]

from rmm_envs.systems.maze.dynamics import CONTROLS, DYNAMICS_NAME  # noqa: E402  (owned by the system; re-exported)


class Dubins3DMazeGuardedEnv(MazeStarts, GuardedEnv):
    """Blocking maze parallel-autonomy env; see the module docstring for the full spec."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    reset_options = ("maze", "state", "goal_cell")
    #: lengths are in pixels; for reading them in metres, a nominal scale of 1 cm per px (the
    #: "Units" paragraph of the module docstring)
    length_unit = "px"
    metres_per_unit = 0.01
    scene: MazeScene | None
    #: a rate disturbance moves the car's position (px/s)
    disturbance_rates = {"x": 0, "y": 1}

    def disturbance_parameters(self) -> dict[str, float]:
        """What a ``mismatch`` scales: the car's speed and the gain on its turn rate."""
        return {"speed": float(self.dynamics.speed), "turn_gain": 1.0}

    def __init__(
        self,
        step_dt: float = 0.1,
        n_path_points: int = 8,
        max_episode_sim_time: float = 300.0,
        goal_cells=(4, 8),
        goal_radius: float = 30.0,
        start_jitter: float = 15.0,
        heading_noise: float = math.pi / 4,
        lookahead: float = 190.0,
        driver_gain: float = 1.0,
        maze_rows: int = 10,
        maze_cols: int = 10,
        speed: float = 10.0,
        r_min: float = 50.0,
        clock: Clock | str | None = None,
        render_mode: str | None = None,
        disturbances=None,
    ) -> None:
        gc = tuple(goal_cells) if isinstance(goal_cells, (tuple, list)) else ()
        check_arguments(
            [
                (finite(step_dt) and step_dt > 0, "step_dt", step_dt, "a finite number > 0"),
                (whole(n_path_points) and n_path_points >= 2, "n_path_points", n_path_points, "an integer >= 2"),
                (
                    finite(max_episode_sim_time) and max_episode_sim_time > 0,
                    "max_episode_sim_time",
                    max_episode_sim_time,
                    "a finite number of seconds > 0 (episodes need a time limit)",
                ),
                (
                    len(gc) == 2 and all(whole(g) for g in gc) and 1 <= gc[0] <= gc[1],
                    "goal_cells",
                    goal_cells,
                    "a pair (min, max) of integers with 1 <= min <= max",
                ),
                (finite(goal_radius) and goal_radius > 0, "goal_radius", goal_radius, "a finite number > 0"),
                (finite(start_jitter) and start_jitter >= 0, "start_jitter", start_jitter, "a finite number >= 0"),
                (
                    finite(heading_noise) and 0 <= heading_noise <= math.pi,
                    "heading_noise",
                    heading_noise,
                    "a number in [0, pi]",
                ),
                (finite(lookahead) and lookahead > 0, "lookahead", lookahead, "a finite number > 0"),
                (finite(driver_gain) and driver_gain > 0, "driver_gain", driver_gain, "a finite number > 0"),
                (
                    whole(maze_rows) and 2 <= maze_rows <= MAX_MAZE_SIDE,
                    "maze_rows",
                    maze_rows,
                    f"an integer in [2, {MAX_MAZE_SIDE}]",
                ),
                (
                    whole(maze_cols) and 2 <= maze_cols <= MAX_MAZE_SIDE,
                    "maze_cols",
                    maze_cols,
                    f"an integer in [2, {MAX_MAZE_SIDE}]",
                ),
                (finite(speed) and speed > 0, "speed", speed, "a finite number > 0"),
                (finite(r_min) and r_min > 0, "r_min", r_min, "a finite number > 0"),
                self.check_render_mode(render_mode),
            ]
        )
        self.step_dt = float(step_dt)
        self.n_path_points = int(n_path_points)
        self.max_episode_sim_time = float(max_episode_sim_time)
        self.goal_cells = (int(gc[0]), int(gc[1]))
        self.goal_radius = float(goal_radius)
        self.start_jitter = float(start_jitter)
        self.heading_noise = float(heading_noise)
        self.maze_shape = (int(maze_rows), int(maze_cols))
        self.render_mode = render_mode
        self.dynamics = Dubins3D(float(speed), float(r_min))
        self.driver = PursuitDriver(self.dynamics.u_max, float(lookahead), float(driver_gain))
        self.clock = make_clock(clock)
        lay = observation_layout()
        self.action_space = GuardianActionSpace.for_dynamics(
            self.dynamics,
            CONTROLS,
            safe_default=system("Dubins3DMaze").make_safe_default(lay),
            dynamics_name=DYNAMICS_NAME,
        )
        low = np.array([0.0] * N_RAYS + [-np.inf, -np.inf, -np.pi], dtype=np.float32)
        high = np.array([np.inf] * N_RAYS + [np.inf, np.inf, np.pi], dtype=np.float32)
        self.observation_space = ObservationBox(low, high, lay)
        self.set_disturbances(disturbances)
        self._state = np.zeros(3)
        self._rays = np.zeros(N_RAYS)
        self._last_active = False

    def begin(self, options: dict) -> np.ndarray:
        maze, state, goal, waypoints = self._start(options)
        self.scene = MazeScene(maze, self.dynamics, N_RAYS)
        self._walls = np.ascontiguousarray(maze.walls)
        self._geom = (self._walls, float(maze.half), float(maze.width), float(maze.height))
        self.goal = np.array([*maze.cells[goal], self.goal_radius])
        self.goal_cell = goal
        self.driver.reset(waypoints)
        self._state = state.copy()
        self._state[2] = (self._state[2] + math.pi) % (2 * math.pi) - math.pi
        return self._state

    def begin_plant(self, parameters: dict[str, float] | None) -> None:
        plant = parameters or self.disturbance_parameters()
        self._plant_speed, self._turn_gain = plant["speed"], plant["turn_gain"]

    # ------------------------------------------------------------------ stepping
    def observe(self) -> np.ndarray:
        x, y, psi = self._state
        maze_rays(*self._geom, x, y, psi, N_RAYS, self._rays)
        obs = np.empty(N_RAYS + 3, dtype=np.float32)
        obs[:N_RAYS] = self._rays
        obs[N_RAYS], obs[N_RAYS + 1], obs[N_RAYS + 2] = self.goal[0] - x, self.goal[1] - y, psi
        return self.sensed(obs, self._sim_time)

    def advance(self, duration: float, active: bool, control) -> Motion:
        """The car's closed-form path under one held turn rate (``control[0]``, clipped to
        ``u_max``), cut at its first wall contact or arrival."""
        if active:
            u = float(np.asarray(control, dtype=float).reshape(-1)[0])
            u = min(max(u, -self.dynamics.u_max), self.dynamics.u_max)
        else:
            u = float(self._nominal[0])
        speed, turn, drift = self.dynamics.speed, u, None
        if self.moves_plant:  # the actuators' turn rate, the plant's speed and gain, the drift
            u = float(self.actuated(np.array([u]), self._sim_time)[0])
            speed, turn, drift = self._plant_speed, u * self._turn_gain, self.drift(self._sim_time, 3)
        path = dubins_path(
            self._state[0],
            self._state[1],
            self._state[2],
            speed,
            turn,
            float(duration),
            np.empty((self.n_path_points, 3)),
            SERIES_COEFFICIENTS,
        )
        if drift is not None:  # x and y move by drift * t on top of the car's own motion, exactly
            path[:, :2] += drift[None, :2] * np.linspace(0.0, float(duration), self.n_path_points)[:, None]
        hit = maze_path_hit(*self._geom, path)
        reached = not hit and path_reaches_disc(path, self.goal[0], self.goal[1], self.goal[2])
        self._state = path[-1].copy()
        self._state[2] = (self._state[2] + math.pi) % (2 * math.pi) - math.pi
        return Motion("collision" if hit else "goal" if reached else None, np.array([u]), self._state)

    def final_speed(self) -> float:
        return self.dynamics.speed

    def driver_control(self) -> np.ndarray:
        return np.array([self.driver.control(self._state)])

    # ------------------------------------------------------------------ accessors and labelling hooks
    def privileged(self) -> dict:
        """The true pose, the maze, the goal ``[x, y, r]``, the car's (constant) speed, the
        simulated time and, when set, the disturbances (strings). **Privileged**."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        out = {
            "state": self._state.copy(),
            "maze": self.scene.maze,
            "goal": self.goal.copy(),
            "speed": self.dynamics.speed,
            "sim_time": self._sim_time,
        }
        if self.disturbances:  # what the world does to the car, for a guardian that models it (hj)
            out["disturbances"] = [str(d) for d in self.disturbances]
        return out

    true_state = property(lambda self: self._state.copy(), doc="The true pose (a copy). **Privileged**.")
    sim_time = property(lambda self: self._sim_time, doc="Simulated seconds since reset.")

    #: poses uniform over the image x [-pi, pi), clear of the walls: the maze env's hook, shared
    sample_states = Dubins3DMazeEnv.sample_states

    def observe_states(self, states, rng=None) -> np.ndarray:
        """This env's observation of poses ``(N, 3)`` in the current episode; ``rng`` is unused."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        st = np.asarray(states, dtype=float)
        out = np.empty((st.shape[0], N_RAYS + 3), dtype=np.float32)
        out[:, :N_RAYS] = self.scene.observe(st)
        out[:, N_RAYS : N_RAYS + 2] = self.goal[:2] - st[:, :2]
        out[:, N_RAYS + 2] = (st[:, 2] + np.pi) % (2 * np.pi) - np.pi
        return out

    def render_frame(self, size: int = 512) -> np.ndarray:
        """The ``rgb_array`` frame described under "Rendering" above."""
        if self.scene is None:
            return _render.Canvas(size, 0, 1, 0, 1).img
        m = self.scene.maze
        side = max(m.width, m.height)
        cv = _render.Canvas(size, 0, side, 0, side)
        X, Y = np.meshgrid(cv.wx, cv.wy)
        cv.img[(m.point_clearance(np.column_stack([X.ravel(), Y.ravel()])) <= 2.0).reshape(size, size)] = (0, 0, 0)
        w = self.driver.waypoints
        for a, b in zip(w[:-1], w[1:], strict=True):
            cv.line(a[0], a[1], b[0], b[1], _render.GREY)
        cv.disc(self.goal[0], self.goal[1], self.goal[2], _render.GREEN)
        cv.disc(self._state[0], self._state[1], 25.0, _render.ORANGE if self._last_active else _render.BLUE)
        return cv.img


parallel_env = parallel_twin(Dubins3DMazeGuardedEnv, "Dubins3DMazeParallel-v0")
