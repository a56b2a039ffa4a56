"""The barrier maths of the HOCBF guardians: pure functions of a state and the episode's scene.

The rows of ``G z <= h`` over ``z = (u1, u2, d_th, d_v)`` (the package docstring derives them),
the inflated radii, the barrier values and the obstacle hardest to satisfy.  Nothing here
keeps state; the guardian, the QP and the recovery manoeuvre all call these functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rmm_envs.driver import desired_heading

__all__ = ["HOCBFParams", "barrier_rows", "barrier_values", "critical_obstacle", "inflated_radii"]


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
    return (x - o[:, 0]) ** 2 + (y - o[:, 1]) ** 2 - radii ** 2


def barrier_rows(state, obstacles: np.ndarray, radii: np.ndarray, goal: np.ndarray, prm: HOCBFParams):
    """Dense ``(G, h)`` of ``G z <= h`` at ``state``: ``K`` barrier rows, the ``u1`` box (two
    rows), the ``u2`` box merged with the speed barriers (two rows), the heading CLF and the
    speed CLF (``K + 6`` rows in all)."""
    x, y, th, v = (float(s) for s in state[:4])
    ox, oy = obstacles[:, 0], obstacles[:, 1]
    dx, dy = x - ox, y - oy
    c, s = math.cos(th), math.sin(th)
    b = dx * dx + dy * dy - radii ** 2
    lfb = 2.0 * v * (dx * c + dy * s)
    lf2b = 2.0 * v * v
    g1 = 2.0 * v * (dy * c - dx * s)
    g2 = 2.0 * (dx * c + dy * s)
    h_bar = lf2b + prm.p1 * lfb + prm.p2 * (lfb + prm.p1 * b)
    K = obstacles.shape[0]
    G = np.zeros((K + 6, 4))
    h = np.zeros(K + 6)
    G[:K, 0], G[:K, 1], h[:K] = -g1, -g2, h_bar
    # u1 box, u2 box merged with the speed barriers (as two rows each for a dense solver)
    G[K, 0], h[K] = 1.0, prm.u1_max
    G[K + 1, 0], h[K + 1] = -1.0, -prm.u1_min
    G[K + 2, 1], h[K + 2] = 1.0, min(prm.u2_max, prm.gamma_vmax * (prm.v_max - v))
    G[K + 3, 1], h[K + 3] = -1.0, -max(prm.u2_min, -prm.gamma_vmin * (v - prm.v_min))
    xh, yh = goal[0] - x, goal[1] - y
    d2 = xh * xh + yh * yh
    d = math.sqrt(d2)
    thw = (th + math.pi) % (2 * math.pi) - math.pi
    e = thw - desired_heading(thw, math.atan2(yh, xh))
    lfv = 2.0 * v * e * (xh * math.sin(thw) - yh * math.cos(thw)) / d2 if d2 > 0 else 0.0
    G[K + 4, 0], G[K + 4, 2], h[K + 4] = 2.0 * e, -1.0, -lfv - prm.lambda_theta * e * e
    v_d = min((d / 2.0) ** 2, d / 2.0)
    ev = v - v_d
    G[K + 5, 1], G[K + 5, 3], h[K + 5] = 2.0 * ev, -1.0, -prm.lambda_v * ev * ev
    return G, h


def critical_obstacle(G: np.ndarray, h: np.ndarray, prm: HOCBFParams) -> int:
    """The obstacle whose barrier row of ``(G, h)`` is hardest to satisfy: the smallest
    ``h_i + max_u LgLf b_i . u`` over the control box and speed limits (negative: no admissible
    control satisfies row ``i``)."""
    K = G.shape[0] - 6
    u2_hi, u2_lo = h[K + 2], -h[K + 3]
    best = h[:K] - np.minimum(G[:K, 0] * prm.u1_min, G[:K, 0] * prm.u1_max) \
        - np.minimum(G[:K, 1] * u2_lo, G[:K, 1] * u2_hi)
    return int(np.argmin(best))
