"""A batched rigid-body propagator for the quadrotor that reproduces PyBullet's integration.

State (13): position, quaternion ``(x, y, z, w)``, linear and angular velocity, all in the
**world** frame (PyBullet's convention).  Control (4): body-frame thrust ``F`` in [0, 8] N
along the body z axis and body-frame moments ``(Mx, My, Mz)`` in [+-2, +-2, +-1] N m.  One
physics step of ``dt = 1/240`` s as PyBullet's multibody integrator does it (semi-implicit
Euler; checked against PyBullet by the tests).  Every number (and the body's mass, inertia and
collision cylinder) is written once, in :class:`QuadrotorParams`; ``QUADROTOR`` is the paper's
quadrotor, which both ``QuadrotorRoom-v0`` (PyBullet) and :class:`Quadrotor` (this propagator)
read.

The forces, the torques, the step and a branch's timing: :class:`Quadrotor`; why a propagator of
our own: docs/decisions/0021-exact-models.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from rmm_envs.systems.quadrotor.rotations import quat_mul, quat_to_rot

__all__ = ["QUADROTOR", "Quadrotor", "QuadrotorParams"]


def _finite_tuple(name: str, value, n: int) -> tuple:
    try:
        t = tuple(float(v) for v in np.asarray(value, dtype=float).reshape(-1))
    except (TypeError, ValueError):
        t = ()
    if len(t) != n or not all(math.isfinite(v) for v in t):
        raise ValueError(f"QuadrotorParams.{name} must be {n} finite numbers, got {value!r}")
    return t


@dataclass(frozen=True)
class QuadrotorParams:
    """Every physical fact of the quadrotor, read by the PyBullet env and the numpy propagator alike.

    The defaults are the paper's body (docs/original-code.md, item 26) in PyBullet's setting:

    * ``mass`` 0.5 kg and ``inertia`` ``diag(0.0023, 0.0023, 0.004)`` kg m^2 (principal
      moments about the body x, y, z axes) -- PyBullet reads them from
      ``rmm_envs/assets/quadrotor.urdf``, which a test holds equal to these values;
    * ``collision_radius`` 0.3 m and ``collision_length`` 0.1 m: the URDF's collision cylinder
      (axis = body z), also used by the analytic room collision;
    * ``gravity`` 9.81 m/s^2 along world -z and the physics step ``dt`` = 1/240 s
      (PyBullet's default step);
    * ``control_low`` / ``control_high``: body thrust ``F`` in [0, 8] N (hover is
      ``mass * gravity`` = 4.905 N) and moments ``(Mx, My, Mz)`` in [+-2, +-2, +-1] N m;
    * ``linear_damping`` / ``angular_damping`` 0.04: PyBullet's default multibody damping
      (the env's arguments replace them);
    * ``max_angular_speed`` 100 rad/s: PyBullet clamps each angular-velocity component there.
    """

    mass: float = 0.5
    inertia: tuple = (0.0023, 0.0023, 0.004)
    collision_radius: float = 0.3
    collision_length: float = 0.1
    gravity: float = 9.81
    dt: float = 1.0 / 240.0
    control_low: tuple = (0.0, -2.0, -2.0, -1.0)
    control_high: tuple = (8.0, 2.0, 2.0, 1.0)
    linear_damping: float = 0.04
    angular_damping: float = 0.04
    max_angular_speed: float = 100.0

    def __post_init__(self) -> None:
        for name in (
            "mass",
            "collision_radius",
            "collision_length",
            "dt",
            "max_angular_speed",
            "gravity",
            "linear_damping",
            "angular_damping",
        ):
            v, positive = getattr(self, name), name not in ("gravity", "linear_damping", "angular_damping")
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float))
                or not math.isfinite(v)
                or v < 0
                or (positive and v == 0)
            ):
                raise ValueError(
                    f"QuadrotorParams.{name} must be a finite number {'>' if positive else '>='} 0, got {v!r}"
                )
        inertia = _finite_tuple("inertia", self.inertia, 3)
        if min(inertia) <= 0:
            raise ValueError(f"QuadrotorParams.inertia must be 3 principal moments > 0, got {self.inertia!r}")
        low, high = (
            _finite_tuple("control_low", self.control_low, 4),
            _finite_tuple("control_high", self.control_high, 4),
        )
        if any(lo > hi for lo, hi in zip(low, high, strict=True)):
            raise ValueError(f"QuadrotorParams: control_low {low} must be <= control_high {high} componentwise")
        object.__setattr__(self, "inertia", inertia)
        object.__setattr__(self, "control_low", low)
        object.__setattr__(self, "control_high", high)

    @property
    def hover_thrust(self) -> float:
        """The thrust (N) that holds the body level and still: ``mass * gravity``."""
        return self.mass * self.gravity


QUADROTOR = QuadrotorParams()
"""The quadrotor of the paper (the env's body and the labeller's dynamics)."""


@dataclass(frozen=True)
class Quadrotor:
    """The batched numpy propagator of the body described by ``params``.

    One physics step of ``dt = 1/240`` s, as PyBullet's multibody integrator does it:

    * forces: gravity, the thrust ``R e_z F``, and damping ``-m (d + d |v|) v`` (PyBullet's
      multibody damping, linear in and proportional to the speed, default ``d = 0.04``);
    * torques: ``R M``, the gyroscopic term ``-w x (I_w w)`` with ``I_w = R I R^T``, and damping
      ``-I_w (d + d |w|) w``;
    * velocities first (``v += a dt``, ``w += alpha dt``), then the position with the new velocity
      and the orientation by the exact rotation ``exp(w dt)``.

    A branch of the risk tree holds one control for ``duration`` split into ``n_steps - 1`` equal
    segments; each segment runs ``ceil(segment / dt)`` physics steps (the original's overshoot to
    whole steps is kept, so a 2 s branch with 8 points lasts 7 x 69 steps).  Quaternion arithmetic
    comes from :mod:`rmm_envs.systems.quadrotor.rotations`."""

    params: QuadrotorParams = QUADROTOR
    state_dim: ClassVar[int] = 13
    control_dim: ClassVar[int] = 4

    def __post_init__(self) -> None:
        if not isinstance(self.params, QuadrotorParams):
            raise TypeError(f"Quadrotor(params=...) needs a QuadrotorParams, got {type(self.params).__name__}")

    @property
    def control_low(self) -> np.ndarray:
        return np.array(self.params.control_low)

    @property
    def control_high(self) -> np.ndarray:
        return np.array(self.params.control_high)

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(self.control_low, self.control_high, size=(n, 4))

    def step(self, s: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One physics step for states ``(N, 13)`` under controls ``(N, 4)`` (already clipped)."""
        par = self.params
        dt, m = par.dt, par.mass
        pos, q, v, w = s[:, 0:3], s[:, 3:7], s[:, 7:10], s[:, 10:13]
        R = quat_to_rot(q)
        I_b = np.asarray(par.inertia)

        # world-frame inertia I_w = R diag(I) R^T, applied to vectors without forming it
        def I_w(x):
            return np.einsum("nij,nj->ni", R, I_b * np.einsum("nji,nj->ni", R, x))

        def I_w_inv(x):
            return np.einsum("nij,nj->ni", R, np.einsum("nji,nj->ni", R, x) / I_b)

        dl, da = par.linear_damping, par.angular_damping
        acc = R[:, :, 2] * (u[:, 0:1] / m)
        acc[:, 2] -= par.gravity
        acc -= (dl + dl * np.linalg.norm(v, axis=1, keepdims=True)) * v
        torque = np.einsum("nij,nj->ni", R, u[:, 1:4])
        Iw = I_w(w)
        torque -= np.cross(w, Iw)
        alpha = I_w_inv(torque) - (da + da * np.linalg.norm(w, axis=1, keepdims=True)) * w
        v_new = v + acc * dt
        w_new = np.clip(w + alpha * dt, -par.max_angular_speed, par.max_angular_speed)
        pos_new = pos + v_new * dt
        # q <- exp(w dt) * q  (world-frame angular velocity)
        ang = np.linalg.norm(w_new, axis=1, keepdims=True) * dt
        with np.errstate(invalid="ignore", divide="ignore"):
            axis = np.where(ang > 1e-12, w_new * dt / np.where(ang > 1e-12, ang, 1.0), 0.0)
        half = 0.5 * ang
        dq = np.concatenate([axis * np.sin(half), np.cos(half)], axis=1)
        q_new = quat_mul(dq, q)
        q_new /= np.linalg.norm(q_new, axis=1, keepdims=True)
        return np.concatenate([pos_new, q_new, v_new, w_new], axis=1)

    def check_propagate(self, states, controls, duration: float, n_steps: int, low=None, high=None):
        """``(states (N, 13), controls (N, 4) clipped to [low, high])`` as floats (default bounds:
        the body's thrust and moments), or ``ValueError`` naming the bad argument."""
        states = np.asarray(states, dtype=float)
        low = self.control_low if low is None else low
        high = self.control_high if high is None else high
        u = np.clip(np.asarray(controls, dtype=float), low, high)
        if states.ndim != 2 or states.shape[1] != 13:
            raise ValueError(f"states must have shape (N, 13), got {states.shape}")
        if u.shape != (states.shape[0], 4):
            raise ValueError(f"controls must have shape ({states.shape[0]}, 4), got {u.shape}")
        if not (math.isfinite(duration) and duration >= 0) or int(n_steps) != n_steps or n_steps < 2:
            raise ValueError(f"need duration >= 0 and n_steps >= 2, got {duration}, {n_steps}")
        return states, u

    def segment_steps(self, duration: float, n_steps: int) -> int:
        """Physics steps per path segment: ``ceil(duration / (n_steps - 1) / dt)`` (whole steps)."""
        return math.ceil(duration / (n_steps - 1) / self.params.dt - 1e-9)

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        states, u = self.check_propagate(states, controls, duration, n_steps)
        per_segment = self.segment_steps(duration, n_steps)
        out = np.empty((states.shape[0], int(n_steps), 13))
        out[:, 0] = s = states
        for k in range(1, int(n_steps)):
            for _ in range(per_segment):
                s = self.step(s, u)
            out[:, k] = s
        return out
