"""The quadrotor's cascaded velocity/attitude controller, and the body flown through it.

A **command** is four numbers in the body's *heading frame* (the world frame turned by the
body's yaw): ``(v_forward, v_left, v_up, yaw_rate)``, within the box of
:class:`CommandController`; zero is *hover and level*.  :func:`command_wrench` turns a command
and a body state (:mod:`rmm_envs.systems.quadrotor.body`) into the body's thrust and moments
``(F, Mx, My, Mz)``, every physics step: a velocity loop, the thrust along the body z axis and
a geometric attitude loop (after Lee, Leok and McClamroch 2010).  :func:`command_wrenches` is
the same function in a compiled loop, serving the batched
:class:`~rmm_envs.systems.quadrotor.closed_loop.ClosedLoopQuadrotor` (the risk labels' dynamics,
whose control *is* the command).  Every physical number is read from
the body's :class:`~rmm_envs.systems.quadrotor.body.QuadrotorParams`.

The loops in full and the gains' reasons: :class:`CommandController`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rmm_envs.autonomy import SafeDefault
from rmm_envs.machine_independent import arctan2
from rmm_envs.systems.quadrotor.body import QUADROTOR, QuadrotorParams

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

__all__ = [
    "CONTROLS",
    "DYNAMICS_NAME",
    "yaw_of",
    "CommandController",
    "HoverAndLevel",
    "body_packed",
    "body_step",
    "command_wrench",
    "command_wrenches",
    "heading_of",
]

#: the guardian action's control fields: the commanded velocity in the heading frame and the yaw rate
CONTROLS = ("vforward_ctrl", "vleft_ctrl", "vup_ctrl", "yawrate_ctrl")
#: the name of these dynamics in its guardian action space's contract (rmm_envs.autonomy.SystemContract)
DYNAMICS_NAME = "quadrotor"

# the layout of the packed gain vector the compiled kernel reads
_MASS, _G, _IX, _IY, _IZ, _KV, _KVZ, _AH, _AZ, _KR, _KW, _KWZ, _FLO, _FHI, _MLO, _MHI = (
    0,
    1,
    2,
    3,
    4,
    5,
    6,
    7,
    8,
    9,
    10,
    11,
    12,
    13,
    14,
    17,
)
_N_GAINS = 20


def _rotation(qx, qy, qz, qw):
    """The rotation matrix of the unit quaternion ``(x, y, z, w)``, row by row (9 numbers): the
    scalar form of :func:`rmm_envs.systems.quadrotor.rotations.quat_to_rot`, for the compiled kernels."""
    return (
        1 - 2 * (qy * qy + qz * qz),
        2 * (qx * qy - qz * qw),
        2 * (qx * qz + qy * qw),
        2 * (qx * qy + qz * qw),
        1 - 2 * (qx * qx + qz * qz),
        2 * (qy * qz - qx * qw),
        2 * (qx * qz - qy * qw),
        2 * (qy * qz + qx * qw),
        1 - 2 * (qx * qx + qy * qy),
    )


def command_wrench(s, cmd, k, out):
    """Thrust and body moments ``out = (F, Mx, My, Mz)`` for state ``s`` (13) and command
    ``cmd`` (4), with the packed gains ``k`` (:attr:`CommandController.packed`); see the
    module docstring.  Returns ``out``."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(s[3], s[4], s[5], s[6])
    h = math.sqrt(r00 * r00 + r10 * r10)  # (cos psi, sin psi) without the trigonometry
    c, sn = (r00 / h, r10 / h) if h > 1e-12 else (1.0, 0.0)
    # velocity loop
    vdx = c * cmd[0] - sn * cmd[1]
    vdy = sn * cmd[0] + c * cmd[1]
    ax = k[_KV] * (vdx - s[7])
    ay = k[_KV] * (vdy - s[8])
    ah = math.sqrt(ax * ax + ay * ay)
    if ah > k[_AH]:
        ax *= k[_AH] / ah
        ay *= k[_AH] / ah
    az = min(max(k[_KVZ] * (cmd[2] - s[9]), -k[_AZ]), k[_AZ])
    fx, fy, fz = ax, ay, az + k[_G]
    # thrust: m f along the current body z axis
    out[0] = min(max(k[_MASS] * (fx * r02 + fy * r12 + fz * r22), k[_FLO]), k[_FHI])
    # desired attitude: z_d along f, x_d in the plane of z_d and the current heading
    fn = math.sqrt(fx * fx + fy * fy + fz * fz)
    zx, zy, zz = fx / fn, fy / fn, fz / fn
    yx, yy, yz = -zz * sn, zz * c, zx * sn - zy * c  # z_d x (cos psi, sin psi, 0)
    yn = math.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / yn, yy / yn, yz / yn
    xx, xy, xz = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    # E = R_d^T R; e_R = vee(E - E^T) / 2
    e01 = xx * r01 + xy * r11 + xz * r21
    e02 = xx * r02 + xy * r12 + xz * r22
    e10 = yx * r00 + yy * r10 + yz * r20
    e12 = yx * r02 + yy * r12 + yz * r22
    e20 = zx * r00 + zy * r10 + zz * r20
    e21 = zx * r01 + zy * r11 + zz * r21
    erx, ery, erz = 0.5 * (e21 - e12), 0.5 * (e02 - e20), 0.5 * (e10 - e01)
    # body angular velocity w_b = R^T w
    wx = r00 * s[10] + r10 * s[11] + r20 * s[12]
    wy = r01 * s[10] + r11 * s[11] + r21 * s[12]
    wz = r02 * s[10] + r12 * s[11] + r22 * s[12]
    ix, iy, iz = k[_IX], k[_IY], k[_IZ]
    mx = ix * (-k[_KR] * erx - k[_KW] * wx) + (wy * iz * wz - wz * iy * wy)
    my = iy * (-k[_KR] * ery - k[_KW] * wy) + (wz * ix * wx - wx * iz * wz)
    mz = iz * (-k[_KR] * erz - k[_KWZ] * (wz - cmd[3])) + (wx * iy * wy - wy * ix * wx)
    out[1] = min(max(mx, k[_MLO]), k[_MHI])
    out[2] = min(max(my, k[_MLO + 1]), k[_MHI + 1])
    out[3] = min(max(mz, k[_MLO + 2]), k[_MHI + 2])
    return out


def _wrench_loop(states, cmds, k, out):
    for i in range(states.shape[0]):
        command_wrench(states[i], cmds[i], k, out[i])
    return out


def body_step(s, u, b, out):
    """One physics step of one body, the arithmetic of :meth:`Quadrotor.step
    <rmm_envs.systems.quadrotor.body.Quadrotor.step>` written out for one state (the tests pin the two
    to each other); ``b`` packs ``(mass, gravity, Ix, Iy, Iz, dt, linear damping, angular
    damping, max angular speed)``.  ``out`` (13) may not be ``s``."""
    m, g, ix, iy, iz, dt, dl, da, wmax = b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7], b[8]
    qx, qy, qz, qw = s[3], s[4], s[5], s[6]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = _rotation(qx, qy, qz, qw)
    vx, vy, vz, wx, wy, wz = s[7], s[8], s[9], s[10], s[11], s[12]
    f = u[0] / m
    vn = math.sqrt(vx * vx + vy * vy + vz * vz)
    lin = dl + dl * vn
    ax = r02 * f - lin * vx
    ay = r12 * f - lin * vy
    az = r22 * f - g - lin * vz
    tx = r00 * u[1] + r01 * u[2] + r02 * u[3]
    ty = r10 * u[1] + r11 * u[2] + r12 * u[3]
    tz = r20 * u[1] + r21 * u[2] + r22 * u[3]
    # I_w w = R (I_b * (R^T w))
    bx = ix * (r00 * wx + r10 * wy + r20 * wz)
    by = iy * (r01 * wx + r11 * wy + r21 * wz)
    bz = iz * (r02 * wx + r12 * wy + r22 * wz)
    iwx = r00 * bx + r01 * by + r02 * bz
    iwy = r10 * bx + r11 * by + r12 * bz
    iwz = r20 * bx + r21 * by + r22 * bz
    tx -= wy * iwz - wz * iwy
    ty -= wz * iwx - wx * iwz
    tz -= wx * iwy - wy * iwx
    # alpha = R ((R^T torque) / I_b) - damping
    cx = (r00 * tx + r10 * ty + r20 * tz) / ix
    cy = (r01 * tx + r11 * ty + r21 * tz) / iy
    cz = (r02 * tx + r12 * ty + r22 * tz) / iz
    wn = math.sqrt(wx * wx + wy * wy + wz * wz)
    ang_d = da + da * wn
    alx = r00 * cx + r01 * cy + r02 * cz - ang_d * wx
    aly = r10 * cx + r11 * cy + r12 * cz - ang_d * wy
    alz = r20 * cx + r21 * cy + r22 * cz - ang_d * wz
    nvx, nvy, nvz = vx + ax * dt, vy + ay * dt, vz + az * dt
    nwx = min(max(wx + alx * dt, -wmax), wmax)
    nwy = min(max(wy + aly * dt, -wmax), wmax)
    nwz = min(max(wz + alz * dt, -wmax), wmax)
    out[0], out[1], out[2] = s[0] + nvx * dt, s[1] + nvy * dt, s[2] + nvz * dt
    ang = math.sqrt(nwx * nwx + nwy * nwy + nwz * nwz) * dt
    if ang > 1e-12:
        sh = math.sin(0.5 * ang)
        dx, dy, dz = nwx * dt / ang * sh, nwy * dt / ang * sh, nwz * dt / ang * sh
    else:
        dx = dy = dz = 0.0
    dw = math.cos(0.5 * ang)
    px = dw * qx + dx * qw + dy * qz - dz * qy
    py = dw * qy - dx * qz + dy * qw + dz * qx
    pz = dw * qz + dx * qy - dy * qx + dz * qw
    pw = dw * qw - dx * qx - dy * qy - dz * qz
    pn = math.sqrt(px * px + py * py + pz * pz + pw * pw)
    out[3], out[4], out[5], out[6] = px / pn, py / pn, pz / pn, pw / pn
    out[7], out[8], out[9], out[10], out[11], out[12] = nvx, nvy, nvz, nwx, nwy, nwz
    return out


if njit is not None:  # one source: the compiled loops run these very functions
    _rotation = njit(cache=True, inline="always")(_rotation)
    command_wrench = njit(cache=True)(command_wrench)
    _wrench_loop = njit(cache=True)(_wrench_loop)
    body_step = njit(cache=True)(body_step)


def body_packed(p: QuadrotorParams) -> np.ndarray:
    """The body's numbers in the order :func:`body_step` reads them."""
    return np.array([p.mass, p.gravity, *p.inertia, p.dt, p.linear_damping, p.angular_damping, p.max_angular_speed])


def command_wrenches(states, commands, packed) -> np.ndarray:
    """:func:`command_wrench` for each row of ``states`` (N, 13) and ``commands`` (N, 4): (N, 4)."""
    states = np.ascontiguousarray(states, dtype=float)
    commands = np.ascontiguousarray(commands, dtype=float)
    return _wrench_loop(states, commands, packed, np.empty((states.shape[0], 4)))


def yaw_of(qx: float, qy: float, qz: float, qw: float) -> float:
    """:func:`heading_of` of one quaternion, in scalar arithmetic (the env's and the pilot's
    per-step path; a test holds the two equal)."""
    return math.atan2(2 * (qx * qy + qz * qw), 1 - 2 * (qy * qy + qz * qz))


def heading_of(q) -> np.ndarray:
    """The yaw ``psi`` (rad) of the body x axis of quaternions ``(..., 4)`` (x, y, z, w)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return arctan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))


@dataclass(frozen=True)
class CommandController:
    """The command box and the gains of the cascaded controller (module docstring).

    Every physics step, :func:`command_wrench`:

    1. **Velocity loop** (outer): the desired world velocity is the command's, rotated by the yaw
       ``psi = atan2(R[1, 0], R[0, 0])`` (0 when the body x axis is vertical).  The desired
       acceleration is ``k_v (v_des - v)`` horizontally, its norm limited to ``a_max_h``, and
       ``k_vz (v_up - v_z)`` vertically, clipped to ``+-a_max_z``; plus gravity:
       ``f = a + g e_z``, the specific force the rotors must produce.
    2. **Thrust**: ``F = m f . R e_z`` (the part of ``m f`` along the body z axis), clipped to the
       body's thrust bounds.
    3. **Attitude loop** (inner, geometric, after Lee, Leok and McClamroch 2010): ``R_d`` has its z
       axis along ``f`` and the body's current yaw; ``e_R = vee(R_d^T R - R^T R_d) / 2``,
       ``e_w = w_b - (0, 0, yaw_rate)`` with ``w_b = R^T w``, and
       ``M = I (-k_R e_R - k_w e_w) + w_b x I w_b`` (body frame), ``k_wz`` about z; each moment
       clipped to the body's bounds.

    Why these numbers: horizontal accelerations up to 5 m/s^2 tilt the body at most
    ``atan(5 / 9.81) = 27`` degrees in level flight and 41 degrees descending at the vertical
    limit of 4 m/s^2; the thrust stays within 8 N (at most ``0.5 sqrt(5^2 + 13.81^2) = 7.3`` N,
    climbing).  ``k_R = 400`` s^-2 and ``k_w = 36`` s^-1 (natural frequency 20 rad/s, damping 0.9)
    make the attitude loop about six times faster than the velocity loop (``k_v = 2.5`` s^-1), and
    ``k_w dt = 0.15`` is well inside the stability of the 240 Hz integrator.

    ``command_low`` / ``command_high``: ``(v_forward, v_left, v_up, yaw_rate)`` bounds (m/s,
    rad/s).  ``k_v``, ``k_vz`` (1/s): velocity gains; ``a_max_h``, ``a_max_z`` (m/s^2): the
    acceleration limits (``a_max_z`` below gravity, so the rotors never push down);
    ``k_R`` (1/s^2), ``k_w``, ``k_wz`` (1/s): attitude gains.  ``params``: the body.
    """

    params: QuadrotorParams = QUADROTOR
    command_low: tuple = (-2.0, -2.0, -1.0, -1.0)
    command_high: tuple = (2.0, 2.0, 1.0, 1.0)
    k_v: float = 2.5
    k_vz: float = 3.0
    a_max_h: float = 5.0
    a_max_z: float = 4.0
    k_R: float = 400.0
    k_w: float = 36.0
    k_wz: float = 10.0
    packed: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.params, QuadrotorParams):
            raise TypeError(f"CommandController(params=...) needs a QuadrotorParams, got {type(self.params).__name__}")
        for name in ("k_v", "k_vz", "a_max_h", "a_max_z", "k_R", "k_w", "k_wz"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"CommandController.{name} must be a finite number > 0, got {v!r}")
        if self.a_max_z >= self.params.gravity:
            raise ValueError(
                f"CommandController.a_max_z must be below gravity ({self.params.gravity}), got {self.a_max_z!r}"
            )
        lo = tuple(float(x) for x in np.asarray(self.command_low, float).reshape(-1))
        hi = tuple(float(x) for x in np.asarray(self.command_high, float).reshape(-1))
        if (
            len(lo) != 4
            or len(hi) != 4
            or not all(math.isfinite(x) for x in lo + hi)
            or not all(a <= 0.0 <= b for a, b in zip(lo, hi, strict=True))
        ):
            raise ValueError(
                f"CommandController: command bounds must be 4 finite numbers each with low <= 0 <= high "
                f"(zero is hover), got {self.command_low!r} and {self.command_high!r}"
            )
        object.__setattr__(self, "command_low", lo)
        object.__setattr__(self, "command_high", hi)
        p = self.params
        k = np.empty(_N_GAINS)
        k[[_MASS, _G, _IX, _IY, _IZ]] = (p.mass, p.gravity, *p.inertia)
        k[[_KV, _KVZ, _AH, _AZ, _KR, _KW, _KWZ]] = (
            self.k_v,
            self.k_vz,
            self.a_max_h,
            self.a_max_z,
            self.k_R,
            self.k_w,
            self.k_wz,
        )
        k[_FLO], k[_FHI] = p.control_low[0], p.control_high[0]
        k[_MLO : _MLO + 3], k[_MHI : _MHI + 3] = p.control_low[1:], p.control_high[1:]
        k.setflags(write=False)
        object.__setattr__(self, "packed", k)

    def wrench(self, state, command) -> np.ndarray:
        """``(F, Mx, My, Mz)`` for one state (13) and one command (4, clipped to the box)."""
        cmd = np.clip(np.asarray(command, dtype=float), self.command_low, self.command_high)
        return command_wrench(np.ascontiguousarray(state, dtype=float), cmd, self.packed, np.empty(4))


class HoverAndLevel(SafeDefault):
    """The quadrotor's safe default: hover and level, the zero command (no velocity, no yaw
    rate), which the controller turns into braking to a stop with the body levelled."""

    description = "hover and level (the zero command)"

    def policy(self, space, rng: np.random.Generator, **options):
        self.check_options(options)
        zero = np.minimum(np.maximum(np.zeros(space.control_dim), space.control_low), space.control_high)
        return lambda observation: zero
