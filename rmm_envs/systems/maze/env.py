"""Dubins3D in procedurally generated mazes: ``Dubins3DMaze-v0``.

The paper's Fig. 1 / Table II system (docs/original-code.md, item 25), as a Gymnasium environment.

## Description

A constant-speed car (:class:`rmm_envs.systems.maze.dynamics.Dubins3D`, 10 px/s, minimum turning radius
50 px) drives through a perfect maze with thick walls (:mod:`rmm_envs.systems.maze.mazes`: 20 x 20
cells of 125 px, walls 12.5 px thick, a 2750 x 2750 px image for the rectangular generator).  It
has no goal: the task is to keep driving without touching a wall.  Units are the paper's
pixels throughout.

## Action space

``Box(-0.2, 0.2, (1,), float32)``: the turn rate in rad/s, held for one step.  Values outside
the bounds are clipped; NaN/inf or a wrong shape raise ``ValueError``.

## Observation space

``Box(0, inf, (8,), float32)``: distances in px along 8 rays at ``psi + k pi / 4``
(``k = 0..7``, counter-clockwise from the heading), to the first wall surface (exact
ray-capsule intersection) or the image border.  No pose, heading or speed, as in the paper.
The space is an :class:`rmm_envs.autonomy.ObservationBox` whose layout has one field,
``"rays"`` (indices 0-7), with ray angles ``k pi / 4``.

## Dynamics

``x' = 10 cos(psi), y' = 10 sin(psi), psi' = u``, integrated exactly; each step lasts
``step_dt`` (default 1 s, 10 px) and is checked as a path of ``n_path_points`` (8) points.

## Rewards and episode end

Reward ``-1`` on the step that touches a wall (a point inside a wall, or a segment between
path points touching one, exactly), else 0.  ``terminated`` on that collision; ``truncated``
after ``max_episode_steps`` (default 1000) steps.

## Starting state

A maze from the seed (generator ``"rectangular"`` by default, ``"honeycomb"`` with
``maze_kind="honeycomb"``, or either at random per episode with ``"mixed"``), then a uniform
state in the image, rejected until it is clear of the walls.
``reset(seed, options={"state": [x, y, psi], "maze": Maze or {"generator": ...}})``
sets either explicitly.  With a given state and a generated maze (from the seed, or from the
given ``generate_maze`` arguments) the maze is redrawn until the state is clear of its walls,
as generation keeps states clear; a state inside a wall of a given ``Maze`` or outside its
image, a state that no drawn maze leaves clear, or a maze option of the wrong type raises
``ValueError``.  Without options the draws are exactly those of generation.

## Risk labelling

The env follows the :class:`rmm_envs.risk.LabelledEnv` protocol: ``risk_scene()`` is the
episode's :class:`rmm_envs.scenes.MazeScene`; ``sample_states(rng, n)`` draws poses uniform over
the image and heading, rejecting those inside a wall; ``observe_states(states)`` is the ray
observation (no random feature: ``rng`` is ignored).

## Info

``state`` (the true pose, privileged), ``steps``; on the last step ``outcome``
(``"collision"`` or ``"timeout"``).

## Arguments

``gym.make("Dubins3DMaze-v0", maze_kind="rectangular", step_dt=1.0, n_path_points=8,
max_episode_steps=1000, speed=10.0, r_min=50.0, render_mode=None)``

## Rendering

``render_mode="rgb_array"``: a 512 x 512 frame of the maze (walls black), the car (blue) and
its rays (grey).
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from rmm_envs.autonomy import ObservationBox, ObservationLayout
from rmm_envs.envs import _render
from rmm_envs.envs.base import (
    LabelledEnvBase,
    check_arguments,
    draw_until,
    finite,
    option_vector,
    rejection_sample,
    whole,
)
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.mazes import MAZE_GENERATORS, Maze, generate_maze
from rmm_envs.systems.maze.scene import MazeScene

__all__ = ["Dubins3DMazeEnv", "MazeScene", "observation_layout"]

N_RAYS = 8


def observation_layout() -> ObservationLayout:
    """The observation's named slices: ``"rays"``, ray ``k`` at ``k pi / 4`` left of the heading."""
    return ObservationLayout.of(("rays", N_RAYS), ray_angles=[k * math.pi / 4 for k in range(N_RAYS)])


def maze_from_option(value, rng: np.random.Generator) -> Maze:
    """The reset option ``maze``: a :class:`Maze` as given, or a dict of :func:`generate_maze`
    arguments drawn from ``rng``; anything else raises ``ValueError`` naming the option."""
    if isinstance(value, Maze):
        return value
    if isinstance(value, dict):
        try:
            return generate_maze(rng, **value)
        except TypeError as e:
            raise ValueError(f"option 'maze': {e}") from None
    raise ValueError(f"option 'maze' must be a Maze or a dict of generate_maze arguments, got {type(value).__name__}")


class Dubins3DMazeEnv(LabelledEnvBase):
    """See the module docstring for the full specification."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    reset_options: tuple[str, ...] = ("state", "maze")

    def __init__(
        self,
        maze_kind: str = "rectangular",
        step_dt: float = 1.0,
        n_path_points: int = 8,
        max_episode_steps: int = 1000,
        speed: float = 10.0,
        r_min: float = 50.0,
        render_mode: str | None = None,
    ):
        check_arguments(
            [
                (
                    maze_kind in MAZE_GENERATORS + ("mixed",),
                    "maze_kind",
                    maze_kind,
                    f"one of {MAZE_GENERATORS + ('mixed',)}",
                ),
                (finite(step_dt) and step_dt > 0, "step_dt", step_dt, "a finite number > 0"),
                (whole(n_path_points) and n_path_points >= 2, "n_path_points", n_path_points, "an integer >= 2"),
                (
                    whole(max_episode_steps) and max_episode_steps >= 1,
                    "max_episode_steps",
                    max_episode_steps,
                    "an integer >= 1",
                ),
                (finite(speed) and speed > 0, "speed", speed, "a finite number > 0"),
                (finite(r_min) and r_min > 0, "r_min", r_min, "a finite number > 0"),
                self.check_render_mode(render_mode),
            ]
        )
        self.maze_kind = maze_kind
        self.step_dt = float(step_dt)
        self.n_path_points = int(n_path_points)
        self.max_episode_steps = int(max_episode_steps)
        self.dynamics = Dubins3D(speed, r_min)
        self.render_mode = render_mode
        u = np.float32(self.dynamics.u_max)
        self.action_space = spaces.Box(-u, u, shape=(1,), dtype=np.float32)
        self.observation_space = ObservationBox(
            np.zeros(N_RAYS, np.float32), np.full(N_RAYS, np.inf, np.float32), observation_layout()
        )
        self.scene: MazeScene | None = None
        self._state = np.zeros(3)
        self._steps = 0

    def _maze_from_option(self, value) -> Maze:
        return maze_from_option(value, self.np_random)

    # ------------------------------------------------------------------ dataset hooks
    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` poses uniform over the image x [-pi, pi), clear of the walls (rejection sampling)."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        m = self.scene.maze
        return rejection_sample(
            rng,
            n,
            3,
            lambda r, k: np.column_stack(
                [r.uniform(0, m.width, k), r.uniform(0, m.height, k), r.uniform(-np.pi, np.pi, k)]
            ),
            lambda cand: m.state_failed(cand[:, :2]),
            "maze poses clear of the walls",
        )

    def observe_states(self, states, rng=None) -> np.ndarray:
        """The ray observation of arbitrary poses ``(N, 3)``; ``rng`` is unused (no random feature)."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        return self.scene.observe(states)

    @property
    def true_state(self) -> np.ndarray:
        return self._state.copy()

    def privileged(self) -> dict:
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        return {"state": self._state.copy(), "maze": self.scene.maze}

    # ------------------------------------------------------------------ episodes
    _MAX_MAZE_DRAWS = 100

    def _draw_maze(self, spec) -> Maze:
        if spec is None:
            generator = (
                self.maze_kind
                if self.maze_kind != "mixed"
                else MAZE_GENERATORS[int(self.np_random.integers(len(MAZE_GENERATORS)))]
            )
            return generate_maze(self.np_random, generator)
        return self._maze_from_option(spec)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        options = self.check_options(options)
        st = option_vector(options["state"], 3, "state", " [x, y, psi]") if "state" in options else None
        spec = options.get("maze")
        if spec is not None and not isinstance(spec, (Maze, dict)):
            self._maze_from_option(spec)  # raises, naming the option
        if st is not None and isinstance(spec, Maze):
            if spec.state_failed(st[None, :2])[0]:
                raise ValueError(
                    f"option 'state': {st[:2].tolist()} is inside a wall of option 'maze' or outside its "
                    f"{spec.width:g} x {spec.height:g} px image"
                )
            maze = spec
        elif st is not None:
            # a generated maze (from the seed, or from the given generate_maze arguments) is
            # redrawn until the given state is clear of its walls, as generation keeps states clear
            maze = draw_until(
                lambda: self._draw_maze(spec), lambda mz: not mz.state_failed(st[None, :2])[0], self._MAX_MAZE_DRAWS
            )
            if maze is None:
                raise ValueError(
                    f"option 'state': {st[:2].tolist()} is inside a wall or outside the image of each of "
                    f"{self._MAX_MAZE_DRAWS} mazes drawn from the seed; choose a point inside a cell, "
                    "away from its sides"
                )
        else:
            maze = self._draw_maze(spec)
        self.scene = MazeScene(maze, self.dynamics)
        if st is None:
            st = self.sample_states(self.np_random, 1)[0]
        self._state = st
        self._steps = 0
        self.begin_episode()
        return self._obs(), {"state": self._state.copy(), "steps": 0}

    def _obs(self) -> np.ndarray:
        assert self.scene is not None  # set by reset, before any observation
        return self.scene.observe(self._state[None])[0]

    def step(self, action):
        self.check_can_step()
        a = np.asarray(action, dtype=float)
        if a.size != 1 or a.ndim > 1:
            raise ValueError(f"action must be a turn rate of shape (1,) in {self.action_space}, got shape {a.shape}")
        u = float(a.reshape(-1)[0])
        if not math.isfinite(u):
            raise ValueError(f"action must be finite (space {self.action_space}), got {u}")
        u = min(max(u, -self.dynamics.u_max), self.dynamics.u_max)
        path = self.dynamics.propagate(self._state[None], np.array([[u]]), self.step_dt, self.n_path_points)
        hit = bool(self.scene.path_failed(path)[0])
        self._state = path[0, -1].copy()
        self._state[2] = (self._state[2] + np.pi) % (2 * np.pi) - np.pi
        self._steps += 1
        terminated = hit
        truncated = not hit and self._steps >= self.max_episode_steps
        info = {"state": self._state.copy(), "steps": self._steps}
        if terminated or truncated:
            self.end_episode()
            info["outcome"] = "collision" if hit else "timeout"
        return self._obs(), (-1.0 if hit else 0.0), terminated, truncated, info

    def render_frame(self) -> np.ndarray:
        size = 512
        assert self.scene is not None, "call reset() before rendering"
        m = self.scene.maze
        cv = _render.Canvas(size, 0, max(m.width, m.height), 0, max(m.width, m.height))
        X, Y = np.meshgrid(cv.wx, cv.wy)
        walls = m.point_clearance(np.column_stack([X.ravel(), Y.ravel()])) <= 2.0
        cv.img[walls.reshape(size, size)] = (0, 0, 0)
        x, y, psi = self._state
        for d, k in zip(self._obs(), range(N_RAYS), strict=True):
            a = psi + k * np.pi / 4
            cv.line(x, y, x + d * np.cos(a), y + d * np.sin(a), _render.GREY)
        cv.disc(x, y, 25.0, _render.BLUE)
        return cv.img
