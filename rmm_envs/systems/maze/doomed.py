"""The maze car's doomed-start test (its spec's ``doomed_test``): whether a start could avoid the
walls for ever or reach the goal first (:func:`maze_escapes`, whose docstring gives the method and
what it can miss)."""

from __future__ import annotations

import numpy as np

from rmm_envs.starts import StartAssessment

__all__ = ["MAZE_DT", "MAZE_METHOD", "MAZE_SEGMENTS", "maze_escapes", "maze_test"]


#: the maze search's control segments, s (20, 40 and 80 px at the default 10 px/s)
MAZE_SEGMENTS = (2.0, 4.0, 8.0)
#: the maze search's sampling interval, s (1 px at the default speed); walls are checked exactly
#: on the segments between samples
MAZE_DT = 0.1
#: the method name stored with each maze assessment
MAZE_METHOD = "search:turns+loop/3x3/14s"


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
