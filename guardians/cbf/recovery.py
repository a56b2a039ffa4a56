"""The ``cbf`` guardian's recovery: a backup manoeuvre about one obstacle, and when it ends.

Pure functions of the state and the scene (:func:`recovery_control` states the manoeuvre; why:
docs/decisions/0014-cbf-safety-filter.md); the guardian keeps the state of a recovery (which
obstacle, which way round).
"""

from __future__ import annotations

import math

import numpy as np

from rmm_guardians.cbf.barrier import BarrierRows, HOCBFParams

__all__ = ["recovery_control", "recovery_done"]


def recovery_control(
    state,
    i: int,
    obstacles: np.ndarray,
    radii: np.ndarray,
    goal: np.ndarray,
    prm: HOCBFParams,
    lap: float,
    v_stuck: float,
    side: float | None = None,
    rows: BarrierRows | None = None,
) -> tuple[np.ndarray, float]:
    """The backup manoeuvre about obstacle ``i`` at ``state``: ``((u1, u2), side)``.  ``side``
    (+1: counter-clockwise tangent, -1: clockwise) overrides the choice of tangent; the side
    used is returned so that a recovery keeps going round the same way.  ``rows``: the
    scene's :class:`BarrierRows` when the caller has one (else built here).

    With ``n`` the outward normal at the car and ``t`` one of the two tangents:

    * the tangent: while the car moves (``v > v_stuck``) the one with ``t . heading >= 0``
      (turning toward it turns the heading away from the centre); when stopped, the one on the
      goal's side;
    * target heading: along ``t``, tilted 45 degrees outward (``t + n``) while inside the margin
      (``b < 0``), so that the car leaves it;
    * ``u1`` turns to the target heading at full rate, proportionally within one lap
      (``err / lap``) so that it does not overshoot while the command is held; while the heading
      points inward it turns the way that rotates it away from the centre (never through it);
    * ``u2``: full braking while the heading points inward (``heading . n < 0``), which with the
      turn makes ``d^2 b/dt^2 > 0`` strictly; full acceleration (up to the speed barrier) once it
      does not, capped by every obstacle's barrier row.  A stopped car facing inward turns in
      place.  Blocked (stopped, on target, the cap forbids moving: where two obstacles overlap),
      it goes round the other way."""
    x, y, th, v = (float(s) for s in state[:4])
    ox, oy = obstacles[i, :2]
    R = float(radii[i])
    dx, dy = x - ox, y - oy
    dist = math.hypot(dx, dy)
    if dist > 0:
        nx, ny = dx / dist, dy / dist
    else:  # at the centre: any direction is outward; take the heading
        nx, ny = math.cos(th), math.sin(th)
    c, s = math.cos(th), math.sin(th)
    hn = c * nx + s * ny  # outward component of the heading
    tx, ty = -ny, nx  # the counter-clockwise tangent
    if side is not None:
        pass
    elif v > v_stuck:
        side = 1.0 if c * tx + s * ty >= 0 else -1.0
    else:
        gx, gy = goal[0] - x, goal[1] - y
        side = 1.0 if gx * tx + gy * ty >= 0 else -1.0
    tx, ty = side * tx, side * ty
    b = dx * dx + dy * dy - R * R
    if b < 0:
        tx, ty = tx + nx, ty + ny
    err = (math.atan2(ty, tx) - th + math.pi) % (2.0 * math.pi) - math.pi
    if hn < 0:  # turn the way that rotates the heading away from the centre, never through it
        away = ny * c - nx * s  # sin(normal angle - heading angle): > 0 turn left
        if away * err < 0:
            err += math.copysign(2.0 * math.pi, away)
    u1 = min(max(err / lap, prm.u1_min), prm.u1_max)
    if hn < 0 and abs(err) > prm.u1_max * lap:
        u2 = prm.u2_min if v > prm.v_min else 0.0
    else:
        u2 = max(0.0, min(prm.u2_max, prm.gamma_vmax * (prm.v_max - v)))
        # accelerate only as far as every barrier row allows with this u1 (another
        # obstacle may lie ahead): row j reads G[j,0] u1 + G[j,1] u2 <= h_j
        G, h = (rows if rows is not None else BarrierRows(obstacles, radii, goal, prm))(state)
        K = obstacles.shape[0]
        cap = math.inf
        for g1, g2, hj in zip(G[:K, 0].tolist(), G[:K, 1].tolist(), h[:K].tolist(), strict=True):
            if g2 > 0:
                cap = min(cap, (hj - g1 * u1) / g2)
        if cap < u2:
            u2 = max(cap, prm.u2_min)
    return np.array([u1, u2]), side


def recovery_done(state, b: np.ndarray, i: int, obstacles: np.ndarray, radii: np.ndarray, goal: np.ndarray) -> bool:
    """Whether a recovery from obstacle ``i`` is over at ``state`` (barrier values ``b``): outside
    every margin, not heading into ``i``, and the straight line to the goal clears inflated ``i``."""
    if any(x < 0 for x in b.tolist()):
        return False
    x, y, th = float(state[0]), float(state[1]), float(state[2])
    ox, oy = obstacles[i, :2]
    dx, dy = x - ox, y - oy
    if dx * math.cos(th) + dy * math.sin(th) < 0:
        return False
    # the straight line to the goal centre must clear the inflated circle i
    gx, gy = goal[0] - x, goal[1] - y
    R2 = float(radii[i]) ** 2
    if (goal[0] - ox) ** 2 + (goal[1] - oy) ** 2 <= R2:
        return True  # the goal overlaps the margin: no detour can clear it; the QP takes over
    L2 = gx * gx + gy * gy
    t = 0.0 if L2 == 0 else min(1.0, max(0.0, -(dx * gx + dy * gy) / L2))
    px, py = dx + t * gx, dy + t * gy
    return px * px + py * py > R2
