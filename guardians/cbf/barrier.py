"""The barrier maths of the HOCBF guardians: pure functions of a state and the episode's scene.

The rows of ``G z <= h`` over ``z = (u1, u2, d_th, d_v)`` (:func:`barrier_rows` derives them),
the inflated radii, the barrier values and the obstacle hardest to satisfy.  Nothing here
keeps state; the guardian, the QP and the recovery manoeuvre all call these functions.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import desired_heading_compiled as _desired_heading

njit: Callable[..., Any] | None  # numba's, or None where numba is missing
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; the Python loop still works
    njit = None

__all__ = [
    "BarrierRows",
    "HOCBFParams",
    "any_row_active",
    "barrier_rows",
    "barrier_values",
    "critical_obstacle",
    "inflated_radii",
]


@dataclass(frozen=True)
class HOCBFParams:
    """Gains and bounds of the rows: class-K gains ``p1, p2``; speed-barrier gains; CLF rates;
    control box ``[u1_min, u1_max] x [u2_min, u2_max]`` and speed range ``[v_min, v_max]``."""

    p1: float
    p2: float
    gamma_vmin: float
    gamma_vmax: float
    lambda_theta: float
    lambda_v: float
    u1_min: float
    u1_max: float
    u2_min: float
    u2_max: float
    v_min: float
    v_max: float


def inflated_radii(obstacles: np.ndarray, goal: np.ndarray, k: float, goal_aware: bool) -> np.ndarray:
    """Each obstacle's barrier radius: ``k r``, or with ``goal_aware`` ``max(r, min(k r, (r + F) / 2))``
    with ``F`` the goal point farthest from the obstacle's centre (a margin never swallows the goal)."""
    r = obstacles[:, 2]
    R = k * r
    if goal_aware and goal.shape[0] >= 3:
        far = np.hypot(goal[0] - obstacles[:, 0], goal[1] - obstacles[:, 1]) + goal[2]
        R = np.maximum(r, np.minimum(R, 0.5 * (r + far)))
    return R


def barrier_values(state, obstacles: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """``b_i`` at ``state`` for every obstacle (``>= 0``: outside the inflated circle)."""
    x, y = float(state[0]), float(state[1])
    o = obstacles
    return (x - o[:, 0]) ** 2 + (y - o[:, 1]) ** 2 - radii**2


def barrier_rows(state, obstacles: np.ndarray, radii: np.ndarray, goal: np.ndarray, prm: HOCBFParams):
    """Dense ``(G, h)`` of ``G z <= h`` at ``state``: ``K`` barrier rows, the ``u1`` box (two
    rows), the ``u2`` box merged with the speed barriers (two rows), the heading CLF and the
    speed CLF (``K + 6`` rows in all).  :class:`BarrierRows` does the same for one scene at
    many states (the guardian's per-decision path).

    For each circular obstacle ``i`` a relative-degree-2 barrier with inflated radius ``R_i``::

        b_i = (x - x_i)^2 + (y - y_i)^2 - R_i^2
        Lf b = 2 v ((x - x_i) cos th + (y - y_i) sin th),   Lf^2 b = 2 v^2
        LgLf b = [2 v ((y - y_i) cos th - (x - x_i) sin th),  2 ((x - x_i) cos th + (y - y_i) sin th)]
        Lf^2 b + LgLf b . u + p1 Lf b + p2 (Lf b + p1 b) >= 0        (linear class-K, p1, p2)

    The heading CLF is the driver's (:func:`rmm_envs.systems.dubins4d.driver.clf_qp`); the speed CLF
    steers toward ``v_d = min((d/2)^2, d/2)`` with ``V_v = (v - v_d)^2`` (the original wrote
    ``(v - v_d) * 82``, a typo for the square; docs/original-code.md, item 13)."""
    return BarrierRows(obstacles, radii, goal, prm)(state)


class BarrierRows:
    """:func:`barrier_rows` for one scene (obstacles, radii, goal, parameters), at any state.

    One compiled loop (numba; the same Python function without it) fills both arrays, from
    arrays prepared here once: the rows are rebuilt at every decision, and numpy's per-call
    overhead on ``K``-element arrays was most of the guardian's decision time."""

    def __init__(self, obstacles: np.ndarray, radii: np.ndarray, goal: np.ndarray, prm: HOCBFParams) -> None:
        self.K = int(obstacles.shape[0])
        self._centres = np.array(obstacles[:, :2], dtype=float, order="C")
        self._radii = np.array(radii, dtype=float, order="C")
        self._gx, self._gy = float(goal[0]), float(goal[1])
        self._q = np.array(
            [
                prm.p1,
                prm.p2,
                prm.gamma_vmin,
                prm.gamma_vmax,
                prm.lambda_theta,
                prm.lambda_v,
                prm.u1_min,
                prm.u1_max,
                prm.u2_min,
                prm.u2_max,
                prm.v_min,
                prm.v_max,
            ],
            dtype=float,
        )

    def __call__(self, state):
        x, y, th, v = state[0], state[1], state[2], state[3]
        G = np.zeros((self.K + 6, 4))
        h = np.zeros(self.K + 6)
        _rows_into(
            G, h, float(x), float(y), float(th), float(v), self._centres, self._radii, self._gx, self._gy, self._q
        )
        return G, h


def _rows_into(G, h, x, y, th, v, centres, radii, gx, gy, q):
    """Fill ``(G, h)`` (zeroed, ``K + 6`` rows) at state ``(x, y, th, v)``; ``q`` holds
    ``p1, p2, gamma_vmin, gamma_vmax, lambda_theta, lambda_v, u1_min,
    u1_max, u2_min, u2_max, v_min, v_max``."""
    p1, p2 = q[0], q[1]
    c, s = math.cos(th), math.sin(th)
    K = centres.shape[0]
    lf2b = 2.0 * v * v
    for i in range(K):
        dx = x - centres[i, 0]
        dy = y - centres[i, 1]
        b = dx * dx + dy * dy - radii[i] * radii[i]
        lfb = 2.0 * v * (dx * c + dy * s)
        G[i, 0] = -(2.0 * v * (dy * c - dx * s))
        G[i, 1] = -(2.0 * (dx * c + dy * s))
        h[i] = lf2b + p1 * lfb + p2 * (lfb + p1 * b)
    # u1 box, u2 box merged with the speed barriers (as two rows each for a dense solver)
    G[K, 0], h[K] = 1.0, q[7]
    G[K + 1, 0], h[K + 1] = -1.0, -q[6]
    G[K + 2, 1], h[K + 2] = 1.0, min(q[9], q[3] * (q[11] - v))
    G[K + 3, 1], h[K + 3] = -1.0, -max(q[8], -q[2] * (v - q[10]))
    xh, yh = gx - x, gy - y
    d2 = xh * xh + yh * yh
    d = math.sqrt(d2)
    thw = (th + math.pi) % (2 * math.pi) - math.pi
    e = thw - _desired_heading(thw, math.atan2(yh, xh))
    lfv = 2.0 * v * e * (xh * math.sin(thw) - yh * math.cos(thw)) / d2 if d2 > 0 else 0.0
    G[K + 4, 0], G[K + 4, 2], h[K + 4] = 2.0 * e, -1.0, -lfv - q[4] * e * e
    v_d = min((d / 2.0) ** 2, d / 2.0)
    ev = v - v_d
    G[K + 5, 1], G[K + 5, 3], h[K + 5] = 2.0 * ev, -1.0, -q[5] * ev * ev


def any_row_active(G: np.ndarray, h: np.ndarray, z: np.ndarray, K: int, atol: float, rtol: float) -> bool:
    """Whether any of the first ``K`` rows (the barriers) of ``G z <= h`` holds with equality
    at ``z``: ``|h_i - G_i z| <= atol + rtol |h_i|`` (the filter is then shaping the control)."""
    for i in range(K):
        gap = h[i] - (G[i, 0] * z[0] + G[i, 1] * z[1] + G[i, 2] * z[2] + G[i, 3] * z[3])
        if abs(gap) <= atol + rtol * abs(h[i]):
            return True
    return False


if njit is not None:  # one source: the compiled loop runs these very functions
    _rows_into = njit(cache=True)(_rows_into)
    any_row_active = njit(cache=True)(any_row_active)


def critical_obstacle(G: np.ndarray, h: np.ndarray, prm: HOCBFParams) -> int:
    """The obstacle whose barrier row of ``(G, h)`` is hardest to satisfy: the smallest
    ``h_i + max_u LgLf b_i . u`` over the control box and speed limits (negative: no admissible
    control satisfies row ``i``)."""
    K = G.shape[0] - 6
    u2_hi, u2_lo = h[K + 2], -h[K + 3]
    best = (
        h[:K]
        - np.minimum(G[:K, 0] * prm.u1_min, G[:K, 0] * prm.u1_max)
        - np.minimum(G[:K, 1] * u2_lo, G[:K, 1] * u2_hi)
    )
    return int(np.argmin(best))
