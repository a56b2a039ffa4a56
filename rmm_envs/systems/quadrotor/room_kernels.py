"""Compiled room collision for one body state: :meth:`RoomCollision.states_failed
<rmm_envs.systems.quadrotor.room_collision.RoomCollision.states_failed>` one state at a time, the same bits.

The quadrotor's fused branch loop (:func:`rmm_envs.scenes.branch_kernels.quadrotor_command_branches`)
tests each path point as soon as it is computed.  :func:`room_state_failed` repeats the numpy
test's floating-point operations in their order: the floor test on the cylinder's lowest point,
the shapes whose centre-level distance is within reach, and the signed distances of the body's
98 points to each of them (``np.linalg.norm`` along an axis is the square root of the squares
summed left to right).  ``np.einsum`` sums its 3-term products in numpy's baseline SIMD code, no
fused multiply-adds: the body points placed in the world (``"kab,pb->kpa"``, both operands
contiguous along the sum) in two lanes, ``(t0 + t2) + t1``; the points in an object's frame
(``"kba,kpb->kpa"``, the rotation strided) left to right.  ``tests/test_fused_labels.py`` pins
it to the numpy test, each distance's bits included, so a numpy that sums otherwise fails there.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; plain Python still works
    njit = None

__all__ = ["room_shape_distance", "room_state_failed", "room_states_failed"]

_WALL, _BOX, _CYLINDER, _SPHERE = -1, 0, 1, 2  # RoomCollision's shape codes (walls are -1)


def _box_sd(px, py, pz, hx, hy, hz):
    """``_box_sd`` of :mod:`rmm_envs.systems.quadrotor.room_collision` for one point."""
    qx, qy, qz = abs(px) - hx, abs(py) - hy, abs(pz) - hz
    mx, my, mz = max(qx, 0.0), max(qy, 0.0), max(qz, 0.0)
    return math.sqrt(mx * mx + my * my + mz * mz) + min(max(max(qx, qy), qz), 0.0)


def room_shape_distance(cx, cy, cz, rot, points, p, shape, idx, walls, obj_pos, obj_R, obj_size):
    """The signed distance from body point ``p`` (``points[p]`` placed by the rotation ``rot``,
    9 numbers row by row, at ``(cx, cy, cz)``) to wall or object ``idx`` of shape ``shape``: the
    entry of numpy's ``sd`` array for that pair."""
    bx, by, bz = points[p, 0], points[p, 1], points[p, 2]
    wx = cx + ((rot[0] * bx + rot[2] * bz) + rot[1] * by)  # np.einsum("kab,pb->kpa"): two lanes, see above
    wy = cy + ((rot[3] * bx + rot[5] * bz) + rot[4] * by)
    wz = cz + ((rot[6] * bx + rot[8] * bz) + rot[7] * by)
    if shape == _WALL:
        return _box_sd(
            wx - walls[idx, 0], wy - walls[idx, 1], wz - walls[idx, 2], walls[idx, 3], walls[idx, 4], walls[idx, 5]
        )
    dx, dy, dz = wx - obj_pos[idx, 0], wy - obj_pos[idx, 1], wz - obj_pos[idx, 2]
    o = obj_R[idx]
    lx = o[0, 0] * dx + o[1, 0] * dy + o[2, 0] * dz  # R^T (x - c)
    ly = o[0, 1] * dx + o[1, 1] * dy + o[2, 1] * dz
    lz = o[0, 2] * dx + o[1, 2] * dy + o[2, 2] * dz
    size = obj_size[idx]
    if shape == _BOX:
        return _box_sd(lx, ly, lz, size[0], size[1], size[2])
    if shape == _CYLINDER:
        dr = math.sqrt(lx * lx + ly * ly) - size[0]
        dh = abs(lz) - size[1] / 2
        mr, mh = max(dr, 0.0), max(dh, 0.0)
        return math.sqrt(mr * mr + mh * mh) + min(max(dr, dh), 0.0)
    return math.sqrt(lx * lx + ly * ly + lz * lz) - size[0]


def room_state_failed(s, rot, points, walls, obj_shape, obj_pos, obj_R, obj_size, obj_radius, geom):
    """Whether body state ``s`` (13; position and quaternion used) fails in the room: one row of
    ``RoomCollision.states_failed``.  ``rot``: a scratch array of 9 floats; ``geom``: the body's
    ``(half length, radius, tolerance, floor tolerance, reach)``."""
    half, radius, tol, floor_tol, reach = geom[0], geom[1], geom[2], geom[3], geom[4]
    cx, cy, cz, x, y, z, w = s[0], s[1], s[2], s[3], s[4], s[5], s[6]
    rot[0], rot[1], rot[2] = 1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)  # quat_to_rot
    rot[3], rot[4], rot[5] = 2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)
    rot[6], rot[7], rot[8] = 2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)
    nz = abs(rot[8])
    if cz - (half * nz + radius * math.sqrt(max(1 - nz * nz, 0.0))) <= floor_tol:
        return True
    for k in range(walls.shape[0]):
        if (
            _box_sd(cx - walls[k, 0], cy - walls[k, 1], cz - walls[k, 2], walls[k, 3], walls[k, 4], walls[k, 5])
            <= reach
        ):
            for p in range(points.shape[0]):
                if room_shape_distance(cx, cy, cz, rot, points, p, _WALL, k, walls, obj_pos, obj_R, obj_size) <= tol:
                    return True
    for k in range(obj_pos.shape[0]):
        dx, dy, dz = cx - obj_pos[k, 0], cy - obj_pos[k, 1], cz - obj_pos[k, 2]
        if math.sqrt(dx * dx + dy * dy + dz * dz) - obj_radius[k] <= reach:
            for p in range(points.shape[0]):
                if (
                    room_shape_distance(cx, cy, cz, rot, points, p, obj_shape[k], k, walls, obj_pos, obj_R, obj_size)
                    <= tol
                ):
                    return True
    return False


def room_states_failed(states, points, walls, obj_shape, obj_pos, obj_R, obj_size, obj_radius, geom, out):
    """:func:`room_state_failed` for each row of ``states`` ``(N, 13)`` into ``out`` ``(N,)``."""
    rot = np.empty(9)
    for i in range(states.shape[0]):
        out[i] = room_state_failed(states[i], rot, points, walls, obj_shape, obj_pos, obj_R, obj_size, obj_radius, geom)
    return out


if njit is not None:  # one source: the compiled kernels are these functions
    _box_sd = njit(cache=True, inline="always")(_box_sd)
    room_shape_distance = njit(cache=True)(room_shape_distance)
    room_state_failed = njit(cache=True)(room_state_failed)
    room_states_failed = njit(cache=True)(room_states_failed)
