"""Quaternion helpers, written once for every caller (quadrotor propagator, room geometry, collision).

Quaternions are ``(x, y, z, w)``, scalar last, as PyBullet stores them; a rotation matrix
``R`` maps body-frame vectors to the world frame (its columns are the body axes in world
coordinates).  Every function takes one quaternion ``(4,)`` or a batch ``(..., 4)`` and keeps
the leading shape.  A batch of products or matrices is the same arithmetic as its rows one at
a time, to the last bit (one batched call can replace a loop of single ones); roll-pitch-yaw
uses numpy's ``sin``/``cos``, whose vectorised loops may differ from one element at a time in
the last bit.  Inputs are assumed to be unit quaternions (nothing is normalised here: the
callers hold unit quaternions and normalising would change their bits).
"""

from __future__ import annotations

import numpy as np

from rmm_envs.machine_independent import norms

__all__ = ["quat_mul", "quat_from_euler", "quat_to_rot", "unit_quaternion_rows"]


def _quats(q, name: str) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.ndim == 0 or q.shape[-1] != 4:
        raise ValueError(f"{name} must have shape (4,) or (..., 4) (x, y, z, w), got shape {q.shape}")
    return q


def quat_to_rot(q) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` of unit quaternions ``(..., 4)`` ``(x, y, z, w)``."""
    q = _quats(q, "q")
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def quat_mul(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` (rotate by ``b``, then by ``a``) of quaternions ``(..., 4)``."""
    a, b = _quats(a, "a"), _quats(b, "b")
    ax, ay, az, aw = (a[..., i] for i in range(4))
    bx, by, bz, bw = (b[..., i] for i in range(4))
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_from_euler(roll, pitch, yaw) -> np.ndarray:
    """The quaternion ``(..., 4)`` of the rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (angles in radians).

    The convention of ``pybullet.getQuaternionFromEuler([roll, pitch, yaw])``: roll about the
    world x axis first, then pitch about y, then yaw about z.
    """
    r, p, y = (np.asarray(v, dtype=float) for v in (roll, pitch, yaw))
    cr, sr, cp, sp, cy, sy = np.cos(r / 2), np.sin(r / 2), np.cos(p / 2), np.sin(p / 2), np.cos(y / 2), np.sin(y / 2)
    return np.stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ],
        axis=-1,
    )


def unit_quaternion_rows(states: np.ndarray) -> np.ndarray:
    """``states`` ``(N, 13)``, refused (``ValueError`` naming the first bad row) unless every
    quaternion (columns 3-6) is a unit quaternion to 1e-6."""
    bad = np.flatnonzero(np.abs(norms(states[:, 3:7]) - 1.0) > 1e-6)
    if bad.size:
        raise ValueError(
            f"states: row {bad[0]} has the quaternion {states[bad[0], 3:7].tolist()}, not a unit quaternion"
        )
    return states
