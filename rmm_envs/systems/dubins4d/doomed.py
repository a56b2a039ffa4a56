"""The Dubins4D car's doomed-start test (its spec's ``doomed_test``): whether an episode's start
among circles could be saved by any control at all (:func:`dubins4d_escapes`, whose docstring gives
the method and what it can miss).  ``docs/concepts.md`` (Doomed starts) gives the measured counts
and cost."""

from __future__ import annotations

import numpy as np

from rmm_envs.starts import StartAssessment

__all__ = ["DUBINS4D_DT", "DUBINS4D_METHOD", "DUBINS4D_SEGMENTS", "dubins4d_escapes", "dubins4d_test"]


#: the control segments' durations, s: together the longest stop (top speed 2 m/s at 0.5 m/s^2)
DUBINS4D_SEGMENTS = (0.5, 1.0, 2.5)
#: the contact check's sampling interval, s (4 cm at the top speed)
DUBINS4D_DT = 0.02
#: the method name stored with each assessment
DUBINS4D_METHOD = "rollout:extreme-controls/3x6/4s"


def _first(hit: np.ndarray) -> np.ndarray:
    """Index of the first True along the last axis, or the axis length where none."""
    return np.where(hit.any(axis=-1), hit.argmax(axis=-1), hit.shape[-1])


def dubins4d_escapes(
    dynamics, state, obstacles, goal, segments=DUBINS4D_SEGMENTS, dt: float = DUBINS4D_DT, first_hit=None
) -> bool:
    """Whether some sequence of extreme controls from ``state`` ``(x, y, theta, v)`` avoids every
    circle of ``obstacles`` ``(K, 3)`` (x, y, r) until it reaches ``goal`` (x, y, r) or the
    segments end; the start is doomed when none does.

    Every sequence of piecewise-constant controls over ``segments`` (by default three covering
    the longest stop, 4 s from the top speed), each segment's control one of the three turn
    rates ``{min, 0, max}`` times the two accelerations ``{min, max}`` (216 sequences), is
    integrated exactly with the car's dynamics and checked for contact with the obstacles
    and the goal every ``dt`` (20 ms: 4 cm at the top speed; a tie counts as a collision, as in
    the env).  One sequence that stays clear (it stopped, or it still moves when the search
    ends) or reaches the goal first makes the start avoidable.  The test is conservative in the
    direction that matters: it assumes a guardian in control from the first instant and counts
    any sequence it cannot prove to collide as an escape, so a doomed start is one that no
    control of the family saves.  What it can miss: a control between the extremes threading a
    gap the extremes miss (such a start is reported avoidable, never the other way round).

    ``first_hit(paths) -> (B,)``, when given, replaces the circles: the index of the first sample
    of each path ``(B, T, 4)`` at or after its first contact (``T``: none), as a map's exact
    contact test gives it (:func:`dubins4d_map_test`)."""
    obstacles = np.asarray(obstacles, float).reshape(-1, 3)
    goal = np.asarray(goal, float)
    lo, hi = dynamics.control_low, dynamics.control_high
    options = np.array([[w, a] for w in (lo[0], 0.0, hi[0]) for a in (lo[1], hi[1])])
    branches = np.asarray(state, float).reshape(1, 4)
    for duration in segments:
        n = max(2, int(round(duration / dt)) + 1)
        times = np.linspace(0.0, duration, n)
        starts = np.repeat(branches, len(options), axis=0)
        controls = np.tile(options, (len(branches), 1))
        paths = dynamics.states_at(starts, controls, times, compiled=False)  # (B, T, 4)
        xy = paths[..., :2]
        if first_hit is not None:
            hits = np.asarray(first_hit(paths))
        elif len(obstacles):
            d2 = ((xy[:, :, None, :] - obstacles[None, None, :, :2]) ** 2).sum(-1)
            hits = _first((d2 <= obstacles[None, None, :, 2] ** 2).any(-1))
        else:
            hits = np.full(xy.shape[0], xy.shape[1])
        at_goal = ((xy - goal[:2]) ** 2).sum(-1) <= goal[2] ** 2
        first_goal = _first(at_goal)
        if np.any(first_goal < hits):  # reached the goal before any contact: saved
            return True
        alive = hits == times.size
        if not alive.any():
            return False
        branches = paths[alive, -1, :]
    return True  # a sequence still clear at the end of the search: not provably doomed


def dubins4d_test(env) -> StartAssessment:
    """The doomed test of a Dubins4D-among-circles env right after ``reset``."""
    inner = env.unwrapped
    scene = inner.scene
    doomed = not dubins4d_escapes(inner.dynamics, inner.true_state, scene.obstacles, scene.goal)
    return StartAssessment(doomed, DUBINS4D_METHOD)
