"""The quadrotor ``hj``'s geometry and kinematics (:mod:`rmm_guardians.hj.quadrotor`): the target of a
room in an altitude band, the velocity loop's closed form, the value's optimal command, and the
pilot's command read from ``info``."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.machine_independent import arctan2
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rooms import bounding_radius
from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_guardians.hj.grid import Grid

__all__ = [
    "angle",
    "lag_prediction",
    "nominal_command",
    "object_top",
    "optimal_command",
    "room_distance",
    "room_target",
]


def room_target(grid: Grid, room, z_lo: float, z_hi: float, radius: float = BOUND, dz: float = 0.1) -> np.ndarray:
    """Signed distance (m) from each position node of ``grid`` to what the room has in the
    altitude band ``[z_lo, z_hi]``, less ``radius``, broadcast over the grid's other axes
    (float32).  Walls (axis-aligned boxes) reaching ``z_lo``: the exact distance to their
    rectangles.  Objects: the least of their 3-D signed distances at heights ``dz`` apart
    through the band, less ``dz / 2`` (the distance is 1-Lipschitz in height), a lower bound on
    the horizontal distance to their cross-sections there (the module docstring)."""
    X, Y = np.meshgrid(grid.axes[0], grid.axes[1], indexing="ij")
    d = np.full(X.shape, 1e3)  # a room with nothing in the band: far everywhere
    for cx, cy, cz, hx, hy, hz in np.asarray(room.walls, float).reshape(-1, 6):
        if cz + hz >= z_lo:
            qx, qy = np.abs(X - cx) - hx, np.abs(Y - cy) - hy
            ox, oy = np.maximum(qx, 0.0), np.maximum(qy, 0.0)
            d = np.minimum(d, np.sqrt(ox * ox + oy * oy) + np.minimum(np.maximum(qx, qy), 0.0))
    n_levels = max(2, int(math.ceil((z_hi - z_lo) / dz)) + 1)
    levels = [z_lo + (z_hi - z_lo) * k / (n_levels - 1) for k in range(n_levels)]
    slack = 0.5 * (z_hi - z_lo) / (n_levels - 1)
    lo, step = grid.lo[:2], grid.dx[:2]
    for o in room.objects:
        size = np.asarray(o["size"], float)
        c = np.asarray(o["pos"], float)
        bound = bounding_radius(o["shape"], size)
        if c[2] - bound > z_hi or c[2] + bound < z_lo:
            continue
        reach = bound + 2.0  # nodes farther than this from the centre are decided by closer things or the cap
        i0, j0 = (max(0, int((c[k] - reach - lo[k]) // step[k])) for k in range(2))
        i1, j1 = (min(grid.n[k], int((c[k] + reach - lo[k]) // step[k]) + 2) for k in range(2))
        if i0 >= i1 or j0 >= j1:
            continue
        R = quat_to_rot(np.asarray(o["quat"], float))
        px, py = X[i0:i1, j0:j1] - c[0], Y[i0:i1, j0:j1] - c[1]
        best = np.full(px.shape, np.inf)
        for z in levels:
            pz = z - c[2]
            # R^T (p - c), the sums written out (no BLAS)
            lx = R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz
            ly = R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz
            lz = R[0, 2] * px + R[1, 2] * py + R[2, 2] * pz
            best = np.minimum(best, _object_sd(o["shape"], size, lx, ly, lz))
        d[i0:i1, j0:j1] = np.minimum(d[i0:i1, j0:j1], best - slack)
    return np.broadcast_to((d - radius)[:, :, None, None].astype(np.float32), grid.shape)


def room_distance(room, points) -> np.ndarray:
    """Exact signed distance (m) from each of ``points`` ``(N, 3)`` to the room: the floor (the
    plane z = 0), its wall boxes and its objects (the body not included: subtract ``BOUND``)."""
    p = np.asarray(points, float).reshape(-1, 3)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    d = z.copy()
    walls = np.asarray(room.walls, float).reshape(-1, 6)
    if walls.size:
        d = np.minimum(
            d,
            _object_sd(
                "box",
                walls[:, 3:].T[:, None, :],
                x[:, None] - walls[:, 0],
                y[:, None] - walls[:, 1],
                z[:, None] - walls[:, 2],
            ).min(axis=1),
        )
    for o in room.objects:
        c, R = np.asarray(o["pos"], float), quat_to_rot(np.asarray(o["quat"], float))
        px, py, pz = x - c[0], y - c[1], z - c[2]
        lx = R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz  # R^T (p - c), the sums written out (no BLAS)
        ly = R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz
        lz = R[0, 2] * px + R[1, 2] * py + R[2, 2] * pz
        d = np.minimum(d, _object_sd(o["shape"], np.asarray(o["size"], float), lx, ly, lz))
    return d


def object_top(o) -> float:
    """The height (m) of the highest point of the room object ``o`` (its exact top)."""
    c, R, size = np.asarray(o["pos"], float), quat_to_rot(np.asarray(o["quat"], float)), np.asarray(o["size"], float)
    if o["shape"] == "box":  # the world-z extent of the three half axes
        return float(c[2] + abs(R[2, 0]) * size[0] + abs(R[2, 1]) * size[1] + abs(R[2, 2]) * size[2])
    if o["shape"] == "cylinder":
        return float(c[2] + abs(R[2, 2]) * size[1] / 2 + size[0] * math.sqrt(max(0.0, 1.0 - R[2, 2] * R[2, 2])))
    return float(c[2] + size[0])


def _object_sd(shape: str, size, x, y, z):
    """Signed distance of the body-frame points ``(x, y, z)`` to a box (half extents), a
    cylinder (radius, length, axis z) or a sphere (radius)."""
    if shape == "sphere":
        return np.sqrt(x * x + y * y + z * z) - size[0]
    if shape == "cylinder":
        qa, qb = np.sqrt(x * x + y * y) - size[0], np.abs(z) - size[1] / 2
        oa, ob = np.maximum(qa, 0.0), np.maximum(qb, 0.0)
        return np.sqrt(oa * oa + ob * ob) + np.minimum(np.maximum(qa, qb), 0.0)
    qa, qb, qc = np.abs(x) - size[0], np.abs(y) - size[1], np.abs(z) - size[2]
    oa, ob, oc = np.maximum(qa, 0.0), np.maximum(qb, 0.0), np.maximum(qc, 0.0)
    return np.sqrt(oa * oa + ob * ob + oc * oc) + np.minimum(np.maximum(np.maximum(qa, qb), qc), 0.0)


def lag_prediction(p, v, c, k: float, t: float):
    """Position and velocity after ``t`` s of the first-order velocity loop ``v' = k (c - v)``
    from ``(p, v)`` (one axis each, scalars): ``v(t) = c + (v - c) e^{-k t}``."""
    e = math.exp(-k * t)
    return p + c * t + (v - c) * (1.0 - e) / k, c + (v - c) * e


def optimal_command(h, vals, c: float, s: float, turn_rate: float, accel: float, k_v: float, v_max: float):
    """The value's optimal command at the horizontal state ``h = (x, y, vx, vy)`` (heading frame,
    heading ``(c, s) = (cos psi, sin psi)``), from ``vals = (V, dV/dx, dV/dy, dV/dtheta, dV/dv)``:
    the bang-bang maximiser of ``grad V . f`` as an acceleration ``a``, commanded as ``v + 2 a /
    k_v`` (the first-order lag still gives at least ``a`` over a lap), its norm held to ``v_max``.
    At rest: ``accel`` straight up the position gradient."""
    gx, gy = float(vals[1]), float(vals[2])
    vx, vy = h[2], h[3]
    sp = math.sqrt(vx * vx + vy * vy)
    ex, ey = (vx / sp, vy / sp) if sp > 1e-9 else (c, s)
    u1 = turn_rate if vals[3] >= 0 else -turn_rate
    u2 = accel if vals[4] >= 0 else -accel
    if sp <= 1e-9:
        gn = math.sqrt(gx * gx + gy * gy)
        ex, ey, u2, u1 = (gx / gn, gy / gn, accel, 0.0) if gn > 0 else (ex, ey, 0.0, 0.0)
    ax, ay = u2 * ex - sp * u1 * ey, u2 * ey + sp * u1 * ex
    ox, oy = vx + 2.0 * ax / k_v, vy + 2.0 * ay / k_v
    on = math.sqrt(ox * ox + oy * oy)
    if on > v_max:  # the value knows no faster flight
        ox, oy = ox * v_max / on, oy * v_max / on
    return (c * ox + s * oy, -s * ox + c * oy)


def angle(y: float, x: float) -> float:
    """The direction of ``(x, y)`` (the portable arctan2: the same bits on every machine)."""
    return float(arctan2(np.array([y]), np.array([x]))[0])


def nominal_command(info) -> np.ndarray:
    """``info["nominal_control"]`` as four finite numbers, refused (naming it) otherwise."""
    if not isinstance(info, dict) or "nominal_control" not in info:
        raise ValueError(
            "guardian 'hj' (quadrotor) needs info['nominal_control'] from the env (the pilot's command), "
            f"got {sorted(info) if isinstance(info, dict) else type(info).__name__}"
        )
    u = np.asarray(info["nominal_control"], float).reshape(-1)
    if u.shape != (4,) or not np.all(np.isfinite(u)):
        raise ValueError(
            f"info['nominal_control'] must be four finite numbers (forward, left, up, yaw rate), "
            f"got {info['nominal_control']!r}"
        )
    return u
