"""A batched rigid-body propagator for the quadrotor that reproduces PyBullet's integration.

State (13): position, quaternion ``(x, y, z, w)``, linear and angular velocity, all in the
**world** frame (PyBullet's convention).  Control (4): body-frame thrust ``F`` in [0, 8] N
along the body z axis and body-frame moments ``(Mx, My, Mz)`` in [+-2, +-2, +-1] N m.

One physics step of ``dt = 1/240`` s, as PyBullet's multibody integrator does it
(semi-implicit Euler; checked against PyBullet by the tests):

* forces: gravity, the thrust ``R e_z F``, and damping ``-m (d + d |v|) v`` (PyBullet's
  multibody damping, linear in and proportional to the speed, default ``d = 0.04``);
* torques: ``R M``, the gyroscopic term ``-w x (I_w w)`` with ``I_w = R I R^T``, and damping
  ``-I_w (d + d |w|) w``;
* velocities first (``v += a dt``, ``w += alpha dt``), then the position with the new
  velocity and the orientation by the exact rotation ``exp(w dt)``.

A branch of the risk tree holds one control for ``duration`` split into ``n_steps - 1``
equal segments; each segment runs ``ceil(segment / dt)`` physics steps (the original's
overshoot to whole steps is kept, so a 2 s branch with 8 points lasts 7 x 69 steps).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Quadrotor", "quat_to_rot"]


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """``(N, 4)`` quaternions ``(x, y, z, w)`` to ``(N, 3, 3)`` rotation matrices."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    return R


@dataclass(frozen=True)
class Quadrotor:
    mass: float = 0.5
    inertia: tuple = (0.0023, 0.0023, 0.004)
    gravity: float = 9.81
    dt: float = 1.0 / 240.0
    linear_damping: float = 0.04
    angular_damping: float = 0.04
    max_angular_speed: float = 100.0  # PyBullet clamps each angular-velocity component here
    state_dim: int = 13
    control_dim: int = 4

    @property
    def control_low(self) -> np.ndarray:
        return np.array([0.0, -2.0, -2.0, -1.0])

    @property
    def control_high(self) -> np.ndarray:
        return np.array([8.0, 2.0, 2.0, 1.0])

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(self.control_low, self.control_high, size=(n, 4))

    def step(self, s: np.ndarray, u: np.ndarray) -> np.ndarray:
        """One physics step for states ``(N, 13)`` under controls ``(N, 4)`` (already clipped)."""
        dt, m = self.dt, self.mass
        pos, q, v, w = s[:, 0:3], s[:, 3:7], s[:, 7:10], s[:, 10:13]
        R = quat_to_rot(q)
        I_b = np.asarray(self.inertia)
        # world-frame inertia I_w = R diag(I) R^T, applied to vectors without forming it
        def I_w(x):
            return np.einsum("nij,nj->ni", R, I_b * np.einsum("nji,nj->ni", R, x))

        def I_w_inv(x):
            return np.einsum("nij,nj->ni", R, np.einsum("nji,nj->ni", R, x) / I_b)

        dl, da = self.linear_damping, self.angular_damping
        acc = R[:, :, 2] * (u[:, 0:1] / m)
        acc[:, 2] -= self.gravity
        acc -= (dl + dl * np.linalg.norm(v, axis=1, keepdims=True)) * v
        torque = np.einsum("nij,nj->ni", R, u[:, 1:4])
        Iw = I_w(w)
        torque -= np.cross(w, Iw)
        alpha = I_w_inv(torque) - (da + da * np.linalg.norm(w, axis=1, keepdims=True)) * w
        v_new = v + acc * dt
        w_new = np.clip(w + alpha * dt, -self.max_angular_speed, self.max_angular_speed)
        pos_new = pos + v_new * dt
        # q <- exp(w dt) * q  (world-frame angular velocity)
        ang = np.linalg.norm(w_new, axis=1, keepdims=True) * dt
        with np.errstate(invalid="ignore", divide="ignore"):
            axis = np.where(ang > 1e-12, w_new * dt / np.where(ang > 1e-12, ang, 1.0), 0.0)
        half = 0.5 * ang
        dq = np.concatenate([axis * np.sin(half), np.cos(half)], axis=1)
        q_new = _quat_mul(dq, q)
        q_new /= np.linalg.norm(q_new, axis=1, keepdims=True)
        return np.concatenate([pos_new, q_new, v_new, w_new], axis=1)

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        states = np.asarray(states, dtype=float)
        u = np.clip(np.asarray(controls, dtype=float), self.control_low, self.control_high)
        if states.ndim != 2 or states.shape[1] != 13:
            raise ValueError(f"states must have shape (N, 13), got {states.shape}")
        if u.shape != (states.shape[0], 4):
            raise ValueError(f"controls must have shape ({states.shape[0]}, 4), got {u.shape}")
        if not (math.isfinite(duration) and duration >= 0) or int(n_steps) != n_steps or n_steps < 2:
            raise ValueError(f"need duration >= 0 and n_steps >= 2, got {duration}, {n_steps}")
        per_segment = math.ceil(duration / (n_steps - 1) / self.dt - 1e-9)
        out = np.empty((states.shape[0], int(n_steps), 13))
        out[:, 0] = s = states
        for k in range(1, int(n_steps)):
            for _ in range(per_segment):
                s = self.step(s, u)
            out[:, k] = s
        return out


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of ``(N, 4)`` quaternions in ``(x, y, z, w)`` order."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=1)
