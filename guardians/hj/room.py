"""The quadrotor ``hj``'s geometry and kinematics (:mod:`guardians.hj.quadrotor`): the target of a
room in an altitude band, and the velocity loop's closed form."""

from __future__ import annotations

import math

import numpy as np

from guardians.hj.grid import Grid
from rmm_envs.systems.rotations import quat_to_rot
from rmm_envs.worlds.room_collision import BOUND

__all__ = ["lag_prediction", "room_target"]


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
        bound = _bounding_radius(o["shape"], size)
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


def _bounding_radius(shape: str, size) -> float:
    if shape == "box":
        return math.sqrt(float(size[0] * size[0] + size[1] * size[1] + size[2] * size[2]))
    return math.hypot(size[0], size[1] / 2) if shape == "cylinder" else float(size[0])


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
