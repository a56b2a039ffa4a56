"""The reckless maze driver: pure pursuit along the maze's cell path, cutting corners.

:class:`PursuitDriver` drives a constant-speed Dubins car (turn rate ``u``, ``|u| <= u_max``)
to a goal cell of a :class:`rmm_envs.systems.maze.mazes.Maze`: it follows the polyline through the
centres of the cells of the maze's unique cell path (:func:`cell_path`), aims at the point
``lookahead`` px further along it than the car's projection, and turns toward it with
``u = clip(gain * bearing error, -u_max, u_max)``.  It ignores the walls and cuts corners on
purpose (``Dubins3DMazeParallel-v0``'s 190 px look-ahead collides in about half the episodes).
The driver is deterministic: all randomness of an episode is in its start.  Why careless:
docs/decisions/0020-reckless-drivers.md.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.maze.routes import cell_distances, cell_of, cell_path  # the maze's routes, shared with guardians

__all__ = ["PursuitDriver", "cell_distances", "cell_of", "cell_path"]


class PursuitDriver:
    """Pure pursuit along the maze's cell path.

    **Plan** (:func:`cell_path`): the maze is a tree of cells joined by passages, so there is
    exactly one cell path from the start to the goal; the driver follows the polyline through the
    centres of its cells (the car's own cell first, the goal cell last).  **Pursue**: each call
    projects the car's position onto the polyline (the nearest point on the current segment or the
    next two, so progress never runs backwards by more than the current segment), takes the point
    ``lookahead`` px further along it (the goal centre once past the end) and turns toward it.

    Careless on purpose: a look-ahead longer than a cell (125 px) starts each turn early and cuts
    across the inner corner, and the car's minimum turning radius (50 px at the maze's defaults) is
    close to half a corridor (56 px from a cell centre to a wall's surface), so a corner taken on
    the inside often grazes the wall's end.  Collisions of the driver alone rise steeply with the
    look-ahead (64-128 episodes each of ``rmm-bench --env Dubins3DMazeParallel-v0 --agent inactive
    --clock fixed:1`` with the env's look-ahead changed): none at 165 px, 23% at 175, 38% at 185,
    40% at 190, 62% at 200, 75% at 210.

    Args:
    u_max: the largest turn rate, rad/s (the system's bound).
    lookahead: how far along the path ahead of the car it aims, px (default 190, the
        env's: a corner is cut from more than a cell away).
    gain: turn rate per radian of bearing error, 1/s (default 1.0: saturates beyond
        ``u_max`` rad of error, 0.2 rad at the maze's defaults).
    """

    def __init__(self, u_max: float, lookahead: float = 190.0, gain: float = 1.0) -> None:
        for name, v in (("u_max", u_max), ("lookahead", lookahead), ("gain", gain)):
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        self.u_max = float(u_max)
        self.lookahead = float(lookahead)
        self.gain = float(gain)
        self.waypoints = np.zeros((0, 2))
        self._seg = 0

    def reset(self, waypoints) -> None:
        """Follow the polyline ``waypoints`` (``(K, 2)``, ``K >= 2``) from its first segment."""
        w = np.asarray(waypoints, dtype=float)
        if w.ndim != 2 or w.shape[1] != 2 or w.shape[0] < 2 or not np.isfinite(w).all():
            raise ValueError(f"waypoints must be (K >= 2, 2) finite points, got shape {w.shape}")
        self.waypoints = w
        self._pts = [(float(x), float(y)) for x, y in w]
        self._len = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(self._pts[:-1], self._pts[1:], strict=True)]
        self._seg = 0

    def target(self, x: float, y: float) -> tuple[float, float]:
        """The point it aims at from position ``(x, y)`` (advances its progress along the path)."""
        pts, lens = self._pts, self._len
        best, best_i, best_t = math.inf, self._seg, 0.0
        for i in range(self._seg, min(self._seg + 3, len(lens))):
            (ax, ay), (bx, by) = pts[i], pts[i + 1]
            L = lens[i]
            t = 0.0 if L == 0 else min(max(((x - ax) * (bx - ax) + (y - ay) * (by - ay)) / (L * L), 0.0), 1.0)
            d = (ax + t * (bx - ax) - x) ** 2 + (ay + t * (by - ay) - y) ** 2
            if d < best:
                best, best_i, best_t = d, i, t
        self._seg = best_i
        i, ahead = best_i, self.lookahead + best_t * lens[best_i]
        while i < len(lens) and ahead > lens[i]:
            ahead -= lens[i]
            i += 1
        if i >= len(lens):
            return pts[-1]
        (ax, ay), (bx, by) = pts[i], pts[i + 1]
        f = ahead / lens[i] if lens[i] > 0 else 0.0
        return ax + f * (bx - ax), ay + f * (by - ay)

    def control(self, state) -> float:
        """The turn rate for pose ``state = (x, y, psi)``."""
        x, y, psi = float(state[0]), float(state[1]), float(state[2])
        tx, ty = self.target(x, y)
        err = (math.atan2(ty - y, tx - x) - psi + math.pi) % (2.0 * math.pi) - math.pi
        return min(max(self.gain * err, -self.u_max), self.u_max)
