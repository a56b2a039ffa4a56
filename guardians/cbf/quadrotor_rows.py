"""The barrier maths of the quadrotor ``cbf``: distances to a generated room, the QP's rows, the QP.

Pure functions of a body state and the episode's room (:class:`rmm_envs.systems.quadrotor.rooms.Room`);
the model, the gains and the margins are derived in :mod:`rmm_guardians.cbf.quadrotor`.  Every part
of the room (floor, walls, boxes, cylinders, spheres) is one convex shape of a flat table
(:class:`RoomShapes`); :func:`shape_distances` gives each shape's signed distance and unit
gradient at a point, and :func:`command_rows` the HOCBF rows ``G u <= h`` over the command
``u = (u_forward, u_left, u_up)`` of the ``n_rows`` shapes nearest the body (smallest barrier
first).  The loops are plain Python compiled by numba, scalar arithmetic only (the same bits on
every CPU).  The rows' derivation: :func:`command_rows`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import osqp
import scipy.sparse as sp

from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_guardians.cbf.backend import QpsolversQP
from rmm_guardians.cbf.quiet import quietly

njit: Callable[..., Any] | None  # numba's, or None where numba is missing
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; the Python loops still work
    njit = None

__all__ = [
    "FLOOR",
    "BOX",
    "CYLINDER",
    "SPHERE",
    "CommandQP",
    "RoomShapes",
    "command_rows",
    "room_shapes",
    "shape_distances",
]

#: OSQP's status values for "solved" and "solved inaccurate".
_SOLVED = (1, 2)

#: The shape codes of :attr:`RoomShapes.code`.
FLOOR, BOX, CYLINDER, SPHERE = 0, 1, 2, 3
_CODES = {"box": BOX, "cylinder": CYLINDER, "sphere": SPHERE}


@dataclass(frozen=True)
class RoomShapes:
    """A room as ``N`` convex shapes: ``code`` ``(N,)`` (:data:`FLOOR`, :data:`BOX`,
    :data:`CYLINDER`, :data:`SPHERE`), ``centre`` ``(N, 3)``, ``rot`` ``(N, 3, 3)`` (local to
    world), ``size`` ``(N, 3)`` (box: half extents; cylinder: radius, length; sphere: radius)."""

    code: np.ndarray
    centre: np.ndarray
    rot: np.ndarray
    size: np.ndarray

    def __len__(self) -> int:
        return int(self.code.shape[0])


def room_shapes(room) -> RoomShapes:
    """The floor, the walls and the objects of ``room`` as :class:`RoomShapes` (in that order).
    An object of another shape is refused (``ValueError`` naming it)."""
    walls = np.asarray(room.walls, float).reshape(-1, 6)
    n = 1 + walls.shape[0] + len(room.objects)
    code = np.empty(n, dtype=np.int64)
    centre, rot, size = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3))
    code[0], rot[0] = FLOOR, np.eye(3)
    code[1 : 1 + walls.shape[0]] = BOX
    centre[1 : 1 + walls.shape[0]], size[1 : 1 + walls.shape[0]] = walls[:, :3], walls[:, 3:]
    rot[1 : 1 + walls.shape[0]] = np.eye(3)
    for i, o in enumerate(room.objects, start=1 + walls.shape[0]):
        if o.get("shape") not in _CODES:
            raise ValueError(
                f"room object {i - 1 - walls.shape[0]} has shape {o.get('shape')!r}; the quadrotor cbf "
                f"models {sorted(_CODES)}"
            )
        s = np.asarray(o["size"], float).reshape(-1)
        code[i] = _CODES[o["shape"]]
        centre[i], size[i, : s.size] = o["pos"], s
        rot[i] = quat_to_rot(np.asarray(o["quat"], float))
    return RoomShapes(code, np.ascontiguousarray(centre), np.ascontiguousarray(rot), np.ascontiguousarray(size))


def _box(qx, qy, qz, a, b, c):
    """Signed distance and gradient of the box ``|x| <= a, |y| <= b, |z| <= c`` at ``(qx, qy, qz)``."""
    ex, ey, ez = abs(qx) - a, abs(qy) - b, abs(qz) - c
    sx, sy, sz = 1.0 if qx >= 0 else -1.0, 1.0 if qy >= 0 else -1.0, 1.0 if qz >= 0 else -1.0
    if ex > 0 or ey > 0 or ez > 0:  # outside: the nearest point is on the box's surface
        ox, oy, oz = max(ex, 0.0), max(ey, 0.0), max(ez, 0.0)
        d = math.sqrt(ox * ox + oy * oy + oz * oz)
        return d, sx * ox / d, sy * oy / d, sz * oz / d
    if ex >= ey and ex >= ez:  # inside: the nearest face
        return ex, sx, 0.0, 0.0
    if ey >= ez:
        return ey, 0.0, sy, 0.0
    return ez, 0.0, 0.0, sz


def _cylinder(qx, qy, qz, r, half):
    """Signed distance and gradient of the cylinder ``x^2 + y^2 <= r^2, |z| <= half``."""
    rho = math.sqrt(qx * qx + qy * qy)
    cx, cy = (qx / rho, qy / rho) if rho > 1e-12 else (1.0, 0.0)
    sz = 1.0 if qz >= 0 else -1.0
    er, ez = rho - r, abs(qz) - half
    if er > 0 or ez > 0:
        orr, oz = max(er, 0.0), max(ez, 0.0)
        d = math.sqrt(orr * orr + oz * oz)
        return d, cx * orr / d, cy * orr / d, sz * oz / d
    if er >= ez:
        return er, cx, cy, 0.0
    return ez, 0.0, 0.0, sz


def shape_distances(p, code, centre, rot, size, d, n):
    """Fill ``d`` ``(N,)`` and ``n`` ``(N, 3)`` with each shape's signed distance and unit
    gradient at the point ``p`` (module docstring)."""
    for i in range(code.shape[0]):
        k = code[i]
        if k == FLOOR:
            d[i], n[i, 0], n[i, 1], n[i, 2] = p[2], 0.0, 0.0, 1.0
            continue
        rx, ry, rz = p[0] - centre[i, 0], p[1] - centre[i, 1], p[2] - centre[i, 2]
        if k == SPHERE:
            dist = math.sqrt(rx * rx + ry * ry + rz * rz)
            if dist > 1e-12:
                d[i], n[i, 0], n[i, 1], n[i, 2] = dist - size[i, 0], rx / dist, ry / dist, rz / dist
            else:
                d[i], n[i, 0], n[i, 1], n[i, 2] = -size[i, 0], 0.0, 0.0, 1.0
            continue
        R = rot[i]
        qx = R[0, 0] * rx + R[1, 0] * ry + R[2, 0] * rz  # R^T (p - c): the local frame
        qy = R[0, 1] * rx + R[1, 1] * ry + R[2, 1] * rz
        qz = R[0, 2] * rx + R[1, 2] * ry + R[2, 2] * rz
        if k == BOX:
            dd, gx, gy, gz = _box(qx, qy, qz, size[i, 0], size[i, 1], size[i, 2])
        else:
            dd, gx, gy, gz = _cylinder(qx, qy, qz, size[i, 0], 0.5 * size[i, 1])
        d[i] = dd
        n[i, 0] = R[0, 0] * gx + R[0, 1] * gy + R[0, 2] * gz  # R g: back to the world
        n[i, 1] = R[1, 0] * gx + R[1, 1] * gy + R[1, 2] * gz
        n[i, 2] = R[2, 0] * gx + R[2, 1] * gy + R[2, 2] * gz
    return d, n


def _command_rows(s, code, centre, rot, size, rho, tau_h, tau_z, p1, p2, d, n, order, G, h, b):
    """Fill the rows of the ``K = order.shape[0]`` shapes nearest the body state ``s`` (13):
    their indices ``order`` (nearest first; on a tie the lower index), ``G`` ``(K, 3)``, ``h``
    and their barrier values ``b`` (``d``, ``n``: work arrays of every shape's distance and
    gradient)."""
    shape_distances(s, code, centre, rot, size, d, n)
    N, K = d.shape[0], order.shape[0]
    taken = np.zeros(N, dtype=np.bool_)
    for j in range(K):  # selection by a strict minimum: the same order on every CPU
        best = -1
        for i in range(N):
            if not taken[i] and (best < 0 or d[i] < d[best]):
                best = i
        taken[best] = True
        order[j] = best
    qx, qy, qz, qw = s[3], s[4], s[5], s[6]
    r00, r10 = 1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy + qz * qw)
    hh = math.sqrt(r00 * r00 + r10 * r10)  # the heading (cos psi, sin psi) as the controller reads it
    c, sn = (r00 / hh, r10 / hh) if hh > 1e-12 else (1.0, 0.0)
    vx, vy, vz = s[7], s[8], s[9]
    for j in range(K):
        i = order[j]
        nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
        bj = d[i] - rho
        nv = nx * vx + ny * vy + nz * vz
        G[j, 0] = -(c * nx + sn * ny) / tau_h  # -(Rot(-psi) n_h) / tau_h
        G[j, 1] = -(-sn * nx + c * ny) / tau_h
        G[j, 2] = -nz / tau_z
        h[j] = (p1 + p2) * nv - (nx * vx + ny * vy) / tau_h - nz * vz / tau_z + p1 * p2 * bj
        b[j] = bj


if njit is not None:  # one source: the compiled loops run these very functions
    _box = njit(cache=True, inline="always")(_box)
    _cylinder = njit(cache=True, inline="always")(_cylinder)
    shape_distances = njit(cache=True)(shape_distances)
    _command_rows = njit(cache=True)(_command_rows)


def command_rows(state, shapes: RoomShapes, n_rows: int, rho: float, tau_h: float, tau_z: float, p1: float, p2: float):
    """``(b, G, h, idx)``: the barrier values, the rows ``G u <= h`` over the heading-frame
    command ``u = (u_forward, u_left, u_up)`` and the shape indices of the ``n_rows`` shapes
    nearest the body at ``state`` (13 numbers: position, quaternion xyzw, world velocity, ...),
    smallest ``b`` first (on a tie, the shape listed first).  The heading is the body's, read as
    the controller reads it (the body x axis projected on the ground).

    A shape's barrier is ``b = d - rho`` (``d`` its signed distance, ``n = grad d`` the outward
    normal at the nearest point; inside, the nearest face's).  With the body's world velocity
    ``v`` and the commanded world velocity ``w`` tracked with first-order lags ``tau_h``
    (horizontal) and ``tau_z`` (vertical)::

        b'  = n . v
        b'' = n_h . (w_h - v_h) / tau_h + n_z (w_z - v_z) / tau_z + v' (Hess d) v
        b'' + (p1 + p2) b' + p1 p2 b >= 0                                       (HOCBF, Xiao & Belta)

    The Hessian term is dropped: the distance to a convex set is convex outside it, so the term
    is ``>= 0`` and leaving it out only tightens the row (it is 0 along a face).  With
    ``w_h = Rot(psi) (u_forward, u_left)`` and ``w_z = u_up``, each shape gives the row::

        G = -(Rot(-psi) n_h / tau_h, n_z / tau_z)
        h = (p1 + p2) n . v - n_h . v_h / tau_h - n_z v_z / tau_z + p1 p2 b
    """
    s = np.ascontiguousarray(state, dtype=float).reshape(-1)
    if s.shape != (13,):
        raise ValueError(
            f"state must be 13 numbers (position, quaternion xyzw, velocity, angular velocity), got shape {s.shape}"
        )
    N = len(shapes)
    K = min(int(n_rows), N)
    order = np.empty(K, dtype=np.int64)
    G, h, b = np.empty((K, 3)), np.empty(K), np.empty(K)
    _command_rows(
        s,
        shapes.code,
        shapes.centre,
        shapes.rot,
        shapes.size,
        float(rho),
        float(tau_h),
        float(tau_z),
        float(p1),
        float(p2),
        np.empty(N),
        np.empty((N, 3)),
        order,
        G,
        h,
        b,
    )
    return b, G, h, order


class CommandQP:
    """``min |u - u_nom|^2 + w s^2  s.t.  G u - s <= h, lo <= u <= hi, 0 <= s <= s_max`` for ``K``
    rows over the 3 velocity commands and one shared slack ``s``: ``s_max = 0`` (``relaxed=False``,
    the strict filter) or ``inf`` (the recovery).  Set up once per episode on the direct OSQP path
    (values and bounds updated per solve, warm-started) or through qpsolvers (``name``)."""

    def __init__(self, K: int, lo, hi, slack_weight: float, eps: float, name: str | None = None) -> None:
        self.K = K
        self.name = name
        P = np.diag([2.0, 2.0, 2.0, 2.0 * slack_weight])
        if name is not None:
            self._qp = QpsolversQP(P, name, eps, lb=np.r_[lo, 0.0], ub=np.r_[hi, 0.0])
            return
        # columns u_f, u_l, u_up (K barrier rows and their box row), s (K barrier rows and its box row)
        A = sp.csc_matrix(np.vstack([np.hstack([np.ones((K, 3)), -np.ones((K, 1))]), np.eye(4)]))
        self._Ax = A.data.copy()
        self._col = A.indptr.copy()
        self._l = np.r_[np.full(K, -np.inf), lo, 0.0]
        self._u = np.r_[np.zeros(K), hi, 0.0]
        self._solver = osqp.OSQP()
        self._solver.setup(
            sp.csc_matrix(P),
            np.zeros(4),
            A,
            self._l,
            self._u,
            verbose=False,
            eps_abs=eps,
            eps_rel=eps,
            polishing=True,
            warm_starting=True,
            max_iter=4000,
        )

    def solve(self, G, h, u_nom, relaxed: bool = False) -> np.ndarray | None:
        """``(u_forward, u_left, u_up, s)`` or ``None`` (infeasible, or the solver failed)."""
        q = np.r_[-2.0 * np.asarray(u_nom, float)[:3], 0.0]
        s_max = math.inf if relaxed else 0.0
        if self.name is not None:
            self._qp.q[:] = q
            assert self._qp.ub is not None  # built with the box bounds (the constructor)
            self._qp.ub[3] = s_max
            return self._qp.solve(np.hstack([G, -np.ones((self.K, 1))]), h)
        for j in range(3):  # column j holds rows 0..K-1 then its box row
            self._Ax[self._col[j] : self._col[j] + self.K] = G[:, j]
        self._u[: self.K] = h
        self._u[-1] = 1e30 if relaxed else 0.0  # OSQP's infinity
        self._solver.update(q=q, Ax=self._Ax, u=self._u)
        res = quietly(self._solver.solve, raise_error=False)
        if res.info.status_val not in _SOLVED or res.x is None or not np.all(np.isfinite(res.x)):
            return None
        return np.asarray(res.x, float)
