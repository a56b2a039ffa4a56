"""Starts of a Dubins4D episode (obstacles, vehicle state, goal): generated, given, or both.

The rules of a start are stated in the "Starting state" section of :mod:`rmm_envs.systems.dubins4d.env`
(the env's spec); this module implements them for :class:`Dubins4DStarts`, a mixin of the env
(the vector env calls :meth:`Dubins4DStarts.generate_start` per sub-env).  Every start obeys:

* R1 the vehicle's position is outside every obstacle (boundary counts as inside);
* R2 the vehicle's position is outside the goal (boundary counts as inside);
* R3 the goal is not entirely inside one obstacle.

Generated parts are rejection-sampled until they obey them against every given part.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.envs.base import draw_until, option_vector
from rmm_envs.systems.dubins4d.circles import CircleWorld, as_circles, points_in_circles
from rmm_envs.systems.dubins4d.doomed import dubins4d_escapes
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, wrap_angle

__all__ = ["AVOIDABLE_ATTEMPTS", "HALF", "STARTS", "Dubins4DStarts"]

HALF = 10.0  # arena half width (generation only)


def goal_inside_obstacle(goal: np.ndarray, obstacles: np.ndarray) -> int | None:
    """Index of an obstacle that contains the whole goal disc (R3), or ``None``."""
    if not obstacles.shape[0]:
        return None
    inside = np.hypot(*(goal[None, :2] - obstacles[:, :2]).T) + goal[2] < obstacles[:, 2]
    return int(np.argmax(inside)) if inside.any() else None


def in_goal(state: np.ndarray, goal: np.ndarray) -> bool:
    """Whether the vehicle's position is inside (or on) the goal disc (R2)."""
    return bool(np.hypot(*(state[:2] - goal[:2])) <= goal[2])


def _parts(given: tuple[str, ...]) -> str:
    return " and ".join(f"option {k!r}" for k in given)


#: the values of the ``starts`` argument: the paper's sampling, or only starts some control saves
STARTS = ("any", "avoidable")
#: draws ``starts="avoidable"`` makes before it gives up
AVOIDABLE_ATTEMPTS = 100


class Dubins4DStarts:
    """Start generation for an env with ``dynamics`` (a Dubins4D), ``n_obstacles``,
    ``obstacle_rad`` and ``goal_rad`` (``(min, max)`` pairs) and ``check_options``."""

    # declared only (no class attributes): the env this mixes into provides them
    dynamics: Dubins4D
    n_obstacles: int
    obstacle_rad: tuple[float, float]
    goal_rad: tuple[float, float]
    check_options: Callable[[dict | None], dict]

    # a vehicle draw lands outside the obstacles about half the time (the arena's free area:
    # 45-62% over 20 seeds), so 100,000 failed draws mean the given parts leave no room
    _MAX_DRAWS = 100_000
    _MAX_OBSTACLE_DRAWS = 1_000  # a state at the arena's centre is left free by ~1 draw in 8

    def _generate_obstacles(
        self, rng: np.random.Generator, state: np.ndarray | None, goal: np.ndarray | None
    ) -> np.ndarray:
        obstacles = draw_until(
            lambda: CircleWorld.generate(rng, self.n_obstacles, *self.obstacle_rad, half_width=HALF),
            lambda obs: (
                not (
                    (state is not None and points_in_circles(state[None, :2], obs)[0])
                    or (goal is not None and goal_inside_obstacle(goal, obs) is not None)
                )
            ),
            self._MAX_OBSTACLE_DRAWS,
        )
        if obstacles is not None:
            return obstacles
        given = " and ".join(
            f"option {k!r} {v[: 2 if k == 'state' else 3].tolist()}"
            for k, v in (("state", state), ("goal", goal))
            if v is not None
        )
        raise ValueError(
            f"could not generate {self.n_obstacles} obstacles clear of {given} in {self._MAX_OBSTACLE_DRAWS} draws; "
            "give 'obstacles' explicitly too"
        )

    def _generate_state(
        self,
        rng: np.random.Generator,
        obstacles: np.ndarray,
        goal: np.ndarray | None = None,
        given: tuple[str, ...] = (),
    ) -> np.ndarray:
        if goal is not None:
            corners = np.array([[-HALF, -HALF], [-HALF, HALF], [HALF, -HALF], [HALF, HALF]])
            if np.all(np.hypot(*(corners - goal[:2]).T) <= goal[2]):  # a disc is convex: it holds the square
                raise ValueError(
                    f"option 'goal' {goal.tolist()} covers the whole arena [-{HALF}, {HALF}]^2 where "
                    "initial states are drawn, so no start outside it exists; give a smaller goal"
                )
        s = self.dynamics
        st = draw_until(
            lambda: np.array(
                [
                    rng.uniform(-HALF, HALF),
                    rng.uniform(-HALF, HALF),
                    rng.uniform(-np.pi, np.pi),
                    rng.uniform(s.v_min, s.v_max),
                ]
            ),
            lambda st: not (points_in_circles(st[None, :2], obstacles)[0] or (goal is not None and in_goal(st, goal))),
            self._MAX_DRAWS,
        )
        if st is not None:
            return st
        if given:
            raise ValueError(
                f"could not draw an initial state on the arena [-{HALF}, {HALF}]^2 outside "
                f"{_parts(given)} in {self._MAX_DRAWS} draws: they leave "
                "too little free space; give 'state' explicitly too"
            )
        raise RuntimeError(f"could not find a collision-free initial state in {self._MAX_DRAWS} draws")

    def _generate_goal(
        self, rng: np.random.Generator, state: np.ndarray, obstacles: np.ndarray, given: tuple[str, ...] = ()
    ) -> np.ndarray:
        g = draw_until(
            lambda: np.array([rng.uniform(-HALF, HALF), rng.uniform(-HALF, HALF), rng.uniform(*self.goal_rad)]),
            lambda g: not in_goal(state, g) and goal_inside_obstacle(g, obstacles) is None,
            self._MAX_DRAWS,
        )
        if g is not None:
            return g
        if given:
            raise ValueError(
                f"could not place a goal around {_parts(given)} in {self._MAX_DRAWS} draws; give 'goal' explicitly too"
            )
        raise RuntimeError(f"could not place a goal in {self._MAX_DRAWS} draws")

    def _given_options(self, options: dict) -> dict:
        """Validate the given parts of a start on their own and against each other (R1-R3)."""
        given: dict[str, np.ndarray] = {}
        state: np.ndarray | None
        goal: np.ndarray | None
        if "obstacles" in options:
            given["obstacles"] = as_circles(options["obstacles"], "option 'obstacles'")
        if "state" in options:
            state = option_vector(options["state"], 4, "state")
            if not (self.dynamics.v_min <= state[3] <= self.dynamics.v_max):
                raise ValueError(
                    f"option 'state': speed must be in [{self.dynamics.v_min}, {self.dynamics.v_max}], got {state[3]}"
                )
            state[2] = wrap_angle(state[2])
            given["state"] = state
        if "goal" in options:
            goal = option_vector(options["goal"], 3, "goal")
            if goal[2] <= 0:
                raise ValueError(f"option 'goal': radius must be > 0, got {goal[2]}")
            given["goal"] = goal
        obstacles, state, goal = given.get("obstacles"), given.get("state"), given.get("goal")
        if state is not None and obstacles is not None:
            hits = [points_in_circles(state[None, :2], o[None, :])[0] for o in obstacles]
            if any(hits):
                i = hits.index(True)
                raise ValueError(
                    f"option 'state': position {state[:2].tolist()} is inside obstacle {i} "
                    f"{obstacles[i].tolist()} of option 'obstacles'"
                )
        if goal is not None and obstacles is not None:
            k = goal_inside_obstacle(goal, obstacles)
            if k is not None:
                raise ValueError(
                    f"option 'goal' {goal.tolist()} lies entirely inside obstacle {k} {obstacles[k].tolist()} "
                    "of option 'obstacles', so it can never be reached (generation never places a goal there)"
                )
        if state is not None and goal is not None and in_goal(state, goal):
            raise ValueError(
                f"option 'state': position {state[:2].tolist()} is already inside option 'goal' {goal.tolist()}"
            )
        return given

    def generate_start(self, rng: np.random.Generator, options: dict[str, Any] | None = None):
        """``(obstacles, state, goal)`` of a new episode drawn from ``rng`` around the reset
        ``options`` (validated); what ``reset`` does (the vector env calls it per sub-env)."""
        given = self._given_options(self.check_options(options))
        # Generation order (obstacles, state, goal) and its draws are those of a reset without
        # options; each generated part is redrawn until it obeys R1-R3 against the given parts.
        obstacles = given.get("obstacles")
        if obstacles is None:
            obstacles = self._generate_obstacles(rng, given.get("state"), given.get("goal"))
        state = given.get("state")
        if state is None:
            state = self._generate_state(
                rng, obstacles, given.get("goal"), tuple(k for k in ("obstacles", "goal") if k in given)
            )
        goal = given.get("goal")
        if goal is None:
            goal = self._generate_goal(rng, state, obstacles, tuple(k for k in ("state", "obstacles") if k in given))
        return obstacles, state, goal

    def _avoidable_start(self, obstacles, state, goal, options):
        """With ``starts="avoidable"``: the start redrawn from the episode's generator (so still a
        function of the seed) until the doomed test (:mod:`rmm_envs.systems.dubins4d.doomed`) finds it avoidable."""
        for _ in range(AVOIDABLE_ATTEMPTS):
            if dubins4d_escapes(self.dynamics, state, obstacles, goal):
                return obstacles, state, goal
            obstacles, state, goal = self.generate_start(self.np_random, options)
        raise RuntimeError(
            f"starts='avoidable': no avoidable start in {AVOIDABLE_ATTEMPTS} draws (reset options "
            f"{sorted(options or {})}); the given parts leave no start that any control saves"
        )
