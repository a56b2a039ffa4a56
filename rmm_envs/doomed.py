"""The built-in doomed tests: whether an episode's start could be saved by any control at all.

Offers :func:`dubins4d_escapes` and :func:`maze_escapes` (the searches; their docstrings give
the method and what it can miss), the env tests :func:`dubins4d_test`, :func:`maze_test` and
:func:`quadrotor_test`, and their settings; each system's spec names its test
(``SystemSpec.doomed_test``, read by :func:`rmm_envs.starts.assess_start`).  Dubins4D among circles and
the maze car are searched (a map's circles, polygons and walls with the map's exact contact
test); a quadrotor start (level and still) is avoidable by hovering.
``docs/concepts.md`` (Doomed starts) gives the measured counts and cost.
"""

from __future__ import annotations

import numpy as np

from rmm_envs.starts import StartAssessment

__all__ = [
    "DUBINS4D_DT",
    "DUBINS4D_METHOD",
    "DUBINS4D_SEGMENTS",
    "MAZE_DT",
    "MAZE_METHOD",
    "MAZE_SEGMENTS",
    "QUADROTOR_METHOD",
    "dubins4d_escapes",
    "dubins4d_map_test",
    "dubins4d_test",
    "maze_escapes",
    "maze_test",
    "quadrotor_test",
]

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


#: the maze search's control segments, s (20, 40 and 80 px at the default 10 px/s)
MAZE_SEGMENTS = (2.0, 4.0, 8.0)
#: the maze search's sampling interval, s (1 px at the default speed); walls are checked exactly
#: on the segments between samples
MAZE_DT = 0.1
#: the method name stored with each maze assessment
MAZE_METHOD = "search:turns+loop/3x3/14s"
#: the method name stored with each quadrotor assessment
QUADROTOR_METHOD = "at-rest:hover"


def _maze_hits(maze, paths: np.ndarray, chunk: int) -> np.ndarray:
    """``(N,)`` index of the first sample after which a path ``(N, T, 2+)`` has touched a wall
    (``T`` when it never does): ``k`` when the segment from sample ``k - 1`` to ``k`` is the
    first to touch one, exactly on the segments between samples.  Paths are checked ``chunk``
    samples at a time (each piece within the walls' look-up reach of its first point), and a
    piece that touches is dated segment by segment, so a goal reached inside the piece before
    its wall still counts as reached first."""
    n, steps = paths.shape[:2]
    first = np.full(n, steps)
    for start in range(0, steps - 1, chunk):
        piece = paths[:, start : min(start + chunk, steps - 1) + 1]
        hit = np.flatnonzero(maze.paths_hit(piece) & (first == steps))
        if hit.size == 0:
            continue
        # date each contact to its segment: every segment of a hitting piece checked on its own
        # (walls looked up from the piece's first point, as for the whole piece)
        segs = piece.shape[1] - 1
        pairs = np.stack([piece[hit, :-1], piece[hit, 1:]], axis=2).reshape(hit.size * segs, 2, -1)
        origin = np.repeat(piece[hit, 0, :2], segs, axis=0)
        seg_hit = maze.paths_hit(pairs, reach_from=origin).reshape(hit.size, segs)
        # a piece that hits has a segment that hits; argmax finds the first
        first[hit] = start + 1 + seg_hit.argmax(axis=1)
    return first


def maze_escapes(dynamics, maze, state, goal, segments=MAZE_SEGMENTS, dt: float = MAZE_DT) -> bool:
    """Whether the maze car at ``state`` ``(x, y, psi)`` can avoid the walls of ``maze`` for ever
    or reach ``goal`` (x, y, r) first; the start is doomed when it cannot.

    The car never stops, so a finite search cannot end in a stop; it ends in a **loop** instead:
    a full-rate turn held for a whole turn is a circle the car can drive for ever, so a pose whose
    left or right loop touches no wall is safe for ever.  The search holds one of the three
    extreme turn rates ``{min, 0, max}`` over each of ``segments`` (by default 2, 4 and 8 s: 27
    sequences), checks every piece exactly against the walls (samples every ``dt``, the segments
    between them exact) and the goal disc (a sample within its radius plus one sample's travel),
    and tries both loops from the start and from the end of every piece that stays clear.  One
    clear loop, or the goal reached before a wall, makes the start avoidable; it is doomed when
    every sequence touches a wall first.  A sequence still clear at the end without a clear loop
    counts as an escape, so, like :func:`dubins4d_escapes`, the test errs towards *avoidable*:
    what it can miss is a turn rate between the extremes threading a gap they miss."""
    speed, u = float(dynamics.speed), float(dynamics.u_max)
    chunk = max(1, int(0.5 * maze.reach / (speed * dt)))  # a piece stays well within the reach
    goal = np.asarray(goal, float)
    reach_goal = (goal[2] + speed * dt) ** 2
    loop_steps = int(np.ceil(2 * np.pi / u / dt)) + 1
    loop_time = (loop_steps - 1) * dt

    def any_loop_clear(poses: np.ndarray) -> bool:
        starts = np.repeat(poses, 2, axis=0)
        turns = np.tile([-u, u], len(poses))
        loops = dynamics.propagate(starts, turns, loop_time, loop_steps)
        return bool((_maze_hits(maze, loops, chunk) == loop_steps).any())

    branches = np.asarray(state, float).reshape(1, 3)
    if any_loop_clear(branches):
        return True
    for duration in segments:
        n = max(2, int(round(duration / dt)) + 1)
        starts = np.repeat(branches, 3, axis=0)
        turns = np.tile([-u, 0.0, u], len(branches))
        paths = dynamics.propagate(starts, turns, duration, n)  # (B, n, 3), the start first
        first_hit = _maze_hits(maze, paths, chunk)
        at_goal = ((paths[..., :2] - goal[:2]) ** 2).sum(-1) <= reach_goal
        first_goal = np.where(at_goal.any(axis=1), at_goal.argmax(axis=1), n)
        if np.any(first_goal < first_hit):  # the goal before any wall: saved
            return True
        alive = first_hit == n
        if not alive.any():
            return False
        branches = paths[alive, -1, :]
        if any_loop_clear(branches):
            return True
    return True  # a sequence still clear at the end of the search: not provably doomed


def maze_test(env) -> StartAssessment:
    """The doomed test of a maze-car guardian env right after ``reset``."""
    inner = env.unwrapped
    doomed = not maze_escapes(inner.dynamics, inner.scene.maze, inner.true_state, inner.goal)
    return StartAssessment(doomed, MAZE_METHOD)


def quadrotor_test(env) -> StartAssessment:
    """The doomed test of a quadrotor guardian env right after ``reset``: a start at rest (every
    generated start is level and still, clear of the room by 0.2 m) is avoidable, since holding
    the hover-and-level command keeps the body where it is (the safe default, which never
    collided in the 2,048 episodes of the quadrotor's Table I); a given start that moves is not
    assessed."""
    state = np.asarray(env.unwrapped.true_state, float)
    if np.abs(state[7:13]).max() > 1e-9:
        return StartAssessment(None, "")
    return StartAssessment(False, QUADROTOR_METHOD)


def dubins4d_map_test(env) -> StartAssessment:
    """The doomed test of a Dubins4D map env right after ``reset``: the same search as among
    circles, with the map's exact contact test (circles, polygons and walls, by pymunk)."""
    inner = env.unwrapped
    scene = inner.scene

    def first_hit(paths: np.ndarray) -> np.ndarray:
        contact = scene.world.first_contacts(paths)  # j + alpha along segment j; inf: none
        return np.where(np.isfinite(contact), np.ceil(np.nan_to_num(contact, posinf=0.0)), paths.shape[1]).astype(int)

    doomed = not dubins4d_escapes(inner.dynamics, inner.true_state, np.zeros((0, 3)), scene.goal, first_hit=first_hit)
    return StartAssessment(doomed, DUBINS4D_METHOD)
