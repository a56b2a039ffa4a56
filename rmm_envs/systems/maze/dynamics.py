"""Dubins3D: a constant-speed car with a bounded turn rate (the paper's "Dubins in mazes").

State ``(x, y, psi)`` (pixels, radians), control ``u`` (rad/s)::

    x' = s cos(psi),   y' = s sin(psi),   psi' = u,   |u| <= s / R_min

Defaults follow the paper's data generation (docs/original-code.md, item 25): speed ``s = 10`` px/s and
minimum turning radius ``R_min = 50`` px, so ``|u| <= 0.2`` rad/s.  Propagation is exact for a
held control (an arc of a circle, or a straight line), batched over ``N`` states.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import _segment

__all__ = ["CONTROLS", "DYNAMICS_NAME", "Dubins3D"]

#: the guardian action's control field (the maze car's turn rate; its guarded envs' action space)
CONTROLS = ("turnrate_ctrl",)
#: the name of these dynamics in its guardian action space's contract (rmm_envs.autonomy.SystemContract)
DYNAMICS_NAME = "dubins3d"


@dataclass(frozen=True)
class Dubins3D:
    speed: float = 10.0
    r_min: float = 50.0
    state_dim: int = 3
    control_dim: int = 1

    def __post_init__(self) -> None:
        if not (self.speed > 0 and self.r_min > 0):
            raise ValueError(f"speed and r_min must be > 0, got {self.speed}, {self.r_min}")

    @property
    def u_max(self) -> float:
        return self.speed / self.r_min

    @property
    def control_low(self) -> np.ndarray:
        return np.array([-self.u_max])

    @property
    def control_high(self) -> np.ndarray:
        return np.array([self.u_max])

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(-self.u_max, self.u_max, size=(n, 1))

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        """``(N, n_steps, 3)`` path under held controls (clipped to the bound)."""
        states = np.asarray(states, dtype=float)
        controls = np.asarray(controls, dtype=float).reshape(-1, 1)
        if states.ndim != 2 or states.shape[1] != 3:
            raise ValueError(f"states must have shape (N, 3), got {states.shape}")
        if controls.shape[0] != states.shape[0]:
            raise ValueError(f"controls must have shape ({states.shape[0]}, 1), got {controls.shape}")
        if not np.isfinite(duration) or duration < 0:
            raise ValueError(f"duration must be a finite number >= 0, got {duration}")
        if int(n_steps) != n_steps or n_steps < 2:
            raise ValueError(f"n_steps must be an integer >= 2, got {n_steps}")
        t = np.linspace(0.0, float(duration), int(n_steps))[None, :]
        w = np.clip(controls, -self.u_max, self.u_max)
        x0, y0, th0 = states[:, 0:1], states[:, 1:2], states[:, 2:3]
        out = np.empty((states.shape[0], t.shape[1], 3))
        out[..., 0], out[..., 1] = _segment(x0, y0, th0, self.speed, w, 0.0, t)
        out[..., 2] = th0 + w * t
        return out
