"""Analytic collision of the quadrotor's body against a generated room (for fast labelling).

The body is the URDF's collision cylinder (radius 0.3 m, length 0.1 m, axis = body z),
represented by 98 points: three rims of 24 points (top, middle, bottom) and two rings of 12
points plus the centres of the two faces.  A body state fails when it comes within a small
tolerance of the room, matching what PyBullet 3.2.7 reports as a contact (measured: the floor
plane from a gap of 9.5 mm, compound boxes from 2 mm): the floor (exact, the cylinder's lowest
point, within 1 cm), a wall box or an object (rotated box, cylinder or sphere) by its signed
distance function (within 2 mm).  States are first pruned by the body's bounding
sphere, so a state far from everything costs a few operations per shape.

Rim sampling errs by at most the sagitta ``0.3 (1 - cos(pi/24)) = 2.6 mm``; the tests compare
verdicts with PyBullet's own contact test.
"""

from __future__ import annotations

import numpy as np

from rmm_envs.systems.quadrotor.body import QUADROTOR
from rmm_envs.systems.quadrotor.rooms import Room, bounding_radius
from rmm_envs.systems.quadrotor.rotations import quat_to_rot

__all__ = ["RoomCollision", "body_points"]

RADIUS, HALF = QUADROTOR.collision_radius, QUADROTOR.collision_length / 2
BOUND = float(np.hypot(RADIUS, HALF))


def body_points() -> np.ndarray:
    pts = []
    a24 = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    a12 = np.linspace(0, 2 * np.pi, 12, endpoint=False) + np.pi / 12
    for z in (-HALF, 0.0, HALF):
        pts += [(RADIUS * np.cos(a), RADIUS * np.sin(a), z) for a in a24]
    for z in (-HALF, HALF):
        pts += [(0.15 * np.cos(a), 0.15 * np.sin(a), z) for a in a12]
        pts.append((0.0, 0.0, z))
    return np.array(pts)


def _box_sd(p, half):
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


class RoomCollision:
    def __init__(self, room: Room, tolerance: float = 2e-3, floor_tolerance: float = 1e-2) -> None:
        self.room = room
        self.tol = float(tolerance)
        self.floor_tol = float(floor_tolerance)
        self.points = body_points()  # (P, 3) in the body frame
        self.walls = np.asarray(room.walls, float).reshape(-1, 6)
        objs = room.objects
        self.obj_shape = np.array([{"box": 0, "cylinder": 1, "sphere": 2}[o["shape"]] for o in objs], dtype=int)
        self.obj_pos = np.array([o["pos"] for o in objs]).reshape(-1, 3)
        self.obj_R = quat_to_rot(np.array([o["quat"] for o in objs]).reshape(-1, 4))
        sizes = np.zeros((len(objs), 3))
        radii = np.zeros(len(objs))
        for i, o in enumerate(objs):
            s = np.asarray(o["size"], float)
            sizes[i, : s.size] = s
            radii[i] = bounding_radius(o["shape"], s)
        self.obj_size, self.obj_radius = sizes, radii

    def kernel_args(self) -> tuple:
        """The room as :func:`rmm_envs.systems.quadrotor.room_kernels.room_state_failed` reads it: ``(points,
        walls, obj_shape, obj_pos, obj_R, obj_size, obj_radius, geom)``, contiguous arrays, ``geom``
        the body's ``(half length, radius, tolerance, floor tolerance, reach)``."""
        c = np.ascontiguousarray
        return (
            c(self.points, dtype=float),
            c(self.walls, dtype=float),
            c(self.obj_shape, dtype=np.int64),
            c(self.obj_pos, dtype=float),
            c(self.obj_R, dtype=float),
            c(self.obj_size, dtype=float),
            c(self.obj_radius, dtype=float),
            np.array([HALF, RADIUS, self.tol, self.floor_tol, BOUND + self.tol]),
        )

    def clearance(self, point) -> float:
        """A lower bound (m) on the gap between the room and the body centred at ``point`` in
        any orientation: the distance from the body's bounding sphere to the floor, to every
        wall box and to every object's bounding sphere (negative when they overlap)."""
        c = np.asarray(point, dtype=float).reshape(3)
        gap = c[2]
        if self.walls.size:
            gap = min(gap, float(_box_sd(c[None, :] - self.walls[:, :3], self.walls[:, 3:]).min()))
        if self.obj_pos.size:
            gap = min(gap, float((np.linalg.norm(self.obj_pos - c, axis=1) - self.obj_radius).min()))
        return gap - BOUND

    def states_failed(self, states: np.ndarray) -> np.ndarray:
        """``(N,)`` bool for body states ``(N, 13)`` (position and quaternion are used)."""
        s = np.asarray(states, float)
        centre = s[:, :3]
        R = quat_to_rot(s[:, 3:7])
        # floor: exact lowest point of the cylinder
        nz = np.abs(R[:, 2, 2])
        low = centre[:, 2] - (HALF * nz + RADIUS * np.sqrt(np.maximum(0.0, 1 - nz * nz)))
        out = low <= self.floor_tol
        reach = BOUND + self.tol
        cand_states, cand_shape, cand_idx = [], [], []
        if self.walls.size:
            sd = _box_sd(centre[:, None, :] - self.walls[None, :, :3], self.walls[None, :, 3:])  # (N, W)
            i, j = np.nonzero(sd <= reach)
            cand_states.append(i)
            cand_shape.append(np.full(i.size, -1))
            cand_idx.append(j)
        if self.obj_pos.size:
            d = np.linalg.norm(centre[:, None, :] - self.obj_pos[None], axis=-1) - self.obj_radius[None]
            i, j = np.nonzero(d <= reach)
            cand_states.append(i)
            cand_shape.append(self.obj_shape[j])
            cand_idx.append(j)
        if not cand_states:
            return out
        i = np.concatenate(cand_states)
        shape = np.concatenate(cand_shape)
        j = np.concatenate(cand_idx)
        keep = ~out[i]
        i, shape, j = i[keep], shape[keep], j[keep]
        if i.size == 0:
            return out
        world = centre[i, None, :] + np.einsum("kab,pb->kpa", R[i], self.points)  # (K, P, 3)
        sd = np.full(world.shape[:2], np.inf)
        w = shape == -1
        if w.any():
            sd[w] = _box_sd(world[w] - self.walls[j[w], None, :3], self.walls[j[w], None, 3:])
        o = ~w
        if o.any():
            local = np.einsum("kba,kpb->kpa", self.obj_R[j[o]], world[o] - self.obj_pos[j[o], None, :])  # R^T (x - c)
            size = self.obj_size[j[o]]
            k = shape[o]
            res = np.empty(local.shape[:2])
            b = k == 0
            res[b] = _box_sd(local[b], size[b][:, None, :])
            c = k == 1
            if c.any():
                dr = np.linalg.norm(local[c][..., :2], axis=-1) - size[c][:, None, 0]
                dz = np.abs(local[c][..., 2]) - size[c][:, None, 1] / 2
                q = np.stack([dr, dz], axis=-1)
                res[c] = np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
            sph = k == 2
            res[sph] = np.linalg.norm(local[sph], axis=-1) - size[sph][:, None, 0]
            sd[o] = res
        hit = (sd <= self.tol).any(axis=1)
        out[i[hit]] = True
        return out
