"""The maze ``hj``'s look-ahead: exact short manoeuvres scored against the walls, the value at their end.

Used by :class:`rmm_guardians.hj.maze.MazeHJGuardian` (``rule="lookahead"``, its default; the
module docstring there says why).  A *manoeuvre* is two held turn rates, ``u1`` for ``t1``
seconds then ``u2`` up to the look-ahead ``H``, with ``u1, u2`` in ``{-u_max, 0, u_max}`` and
``t1`` in ``H / 6`` steps (:func:`manoeuvres`: 36 of them).  Its *score* from a pose is the
smaller of the exact clearance along its path (sampled every ``dt`` seconds, less the half
sample spacing, so that it bounds the clearance between samples from below: the clearance is
1-Lipschitz along the path) and the value ``V`` at its end pose: the first ``H`` seconds are
checked against the true walls, and only the rest relies on the grid value.

:func:`path_clearances` is compiled by numba (scalar loops, the env's own closed forms for the
car's path), so it gives the same bits on every machine.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import SERIES_COEFFICIENTS, segment_position
from rmm_envs.systems.maze.maze_kernels import _seg_point_sq

njit: Callable[..., Any] | None  # numba's, or None where numba is missing
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

__all__ = ["manoeuvres", "path_clearances", "near_walls"]


def manoeuvres(u_max: float, horizon: float, steps: int = 6) -> np.ndarray:
    """``(M, 4)`` rows ``(u1, t1, u2, t2)``: hold ``u1`` for ``t1`` s, then ``u2`` for ``t2`` s:
    until ``horizon`` when ``u2 = 0``, a whole loop (``2 pi / u_max``) when it turns."""
    us = (-u_max, 0.0, u_max)
    loop = 2.0 * math.pi / u_max
    rows = [(b, 0.0, b, loop if b else horizon) for b in us]
    for k in range(1, steps):
        t1 = horizon * k / steps
        rows += [(a, t1, b, loop if b else horizon - t1) for a in us for b in us if a != b]
    return np.array(rows, dtype=float)


def near_walls(walls: np.ndarray, x: float, y: float, reach: float, half: float) -> np.ndarray:
    """The walls (rows ``x0, y0, x1, y1``) whose segment comes within ``reach + half`` of
    ``(x, y)``: the only ones a path of length ``reach`` from there can touch."""
    w = np.asarray(walls, float)
    dx, dy = w[:, 2] - w[:, 0], w[:, 3] - w[:, 1]
    dd = dx * dx + dy * dy
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.clip(np.where(dd > 0, ((x - w[:, 0]) * dx + (y - w[:, 1]) * dy) / dd, 0.0), 0.0, 1.0)
    ex, ey = w[:, 0] + t * dx - x, w[:, 1] + t * dy - y
    r = reach + half
    return np.ascontiguousarray(w[ex * ex + ey * ey <= r * r])


def path_clearances(x, y, psi, speed, man, dt, walls, half, width, height, coef, clear, ends):
    """For each manoeuvre row ``(u1, t1, u2, t2)`` of ``man`` from pose ``(x, y, psi)``: the
    least clearance to ``walls`` (capsules of half-width ``half``) over samples every ``dt`` s
    up to ``t1 + t2``, less ``speed dt / 2`` (a lower bound between samples), into ``clear[m]``
    (``-1`` when a sample leaves the image ``[0, width] x [0, height]``), and the end pose
    into ``ends[m]``."""
    slack = 0.5 * speed * dt
    for m in range(man.shape[0]):
        u1, t1, u2 = man[m, 0], man[m, 1], man[m, 2]
        horizon = t1 + man[m, 3]
        n = int(math.ceil(horizon / dt - 1e-9))
        x1, y1 = segment_position(x, y, psi, speed, u1, 0.0, t1, coef)
        p1 = psi + u1 * t1
        best = np.inf
        ex, ey, ep = x, y, psi
        for k in range(n + 1):
            t = min(k * dt, horizon)
            if t <= t1:
                ex, ey = segment_position(x, y, psi, speed, u1, 0.0, t, coef)
                ep = psi + u1 * t
            else:
                ex, ey = segment_position(x1, y1, p1, speed, u2, 0.0, t - t1, coef)
                ep = p1 + u2 * (t - t1)
            if not (0.0 <= ex <= width and 0.0 <= ey <= height):
                best = -1.0
                break
            d2 = np.inf
            for w in range(walls.shape[0]):
                d2 = min(d2, _seg_point_sq(walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3], ex, ey))
            best = min(best, math.sqrt(d2) - half - slack)
        clear[m] = best
        ends[m, 0], ends[m, 1], ends[m, 2] = ex, ey, ep
    return clear


if njit is not None:
    path_clearances = njit(cache=True)(path_clearances)

COEF = SERIES_COEFFICIENTS
