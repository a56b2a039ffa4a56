"""The HJ dynamics contract, as code, and the systems that satisfy it.

:class:`HJDynamics` is what :func:`rmm_guardians.hj.solver.solve_brt` needs of a system (a
``typing.Protocol``, checked at run time by :func:`check_dynamics`): ``key()`` (the value
cache's identity), ``hamiltonian(grid, p)`` (``max_u min_d p . f(x, u, d)`` for the co-state
``p``, one array per axis: the control avoids the target, the disturbance reaches it; with
``control="min"`` for reach-avoid) and ``alphas(grid)`` (per axis, a bound on ``|dH/dp_i|`` for
the Lax-Friedrichs dissipation and the CFL step).  :class:`HJControlDynamics` adds
``optimal_control(x, grad)``, the bang-bang maximiser a guardian applies.  New dynamics are
frozen dataclasses with these methods.  Offered: :class:`Dubins4DHJ` (the guardians' model) and,
for accuracy tests, :class:`DoubleIntegrator1D`, :class:`Integrator1D`, :class:`Translation`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import Dubins4D

__all__ = [
    "DoubleIntegrator1D",
    "Dubins4DHJ",
    "HJControlDynamics",
    "HJDynamics",
    "Integrator1D",
    "Translation",
    "check_dynamics",
]


@runtime_checkable
class HJDynamics(Protocol):
    """What the level-set solver needs of a system (see the module docstring)."""

    def key(self) -> dict:
        """A JSON-able identity: equal keys mean equal Hamiltonians (the value cache's key)."""
        ...

    def hamiltonian(self, grid, p: Sequence[np.ndarray]) -> np.ndarray:
        """``max_u min_d p . f`` on ``grid`` (float32, the grid's shape) for the co-state ``p``;
        dynamics used for reach-avoid also take ``control="min"`` (the control minimises)."""
        ...

    def alphas(self, grid) -> Sequence:
        """Per axis, a bound on ``|dH/dp_i|`` over the grid (a number or a broadcastable array)."""
        ...


@runtime_checkable
class HJControlDynamics(HJDynamics, Protocol):
    """An :class:`HJDynamics` a guardian acts with: also the optimal control at a state."""

    def optimal_control(self, x, grad, control: str = "max") -> tuple:
        """The bang-bang control maximising (``"max"``: avoid) or minimising (reach) ``grad . f``."""
        ...


def check_dynamics(dynamics) -> HJDynamics:
    """``dynamics`` if it satisfies :class:`HJDynamics`; a ``TypeError`` naming what it lacks otherwise."""
    missing = [m for m in ("key", "hamiltonian", "alphas") if not callable(getattr(dynamics, m, None))]
    if missing:
        raise TypeError(
            f"HJ dynamics must offer key(), hamiltonian(grid, p) and alphas(grid) "
            f"(rmm_guardians.hj.dynamics.HJDynamics); {dynamics!r} lacks {', '.join(missing)}"
        )
    return dynamics


@dataclass(frozen=True)
class Dubins4DHJ:
    """The Dubins4D dynamics (:class:`rmm_envs.systems.dubins4d.dynamics.Dubins4D`) as the solver sees it:
    state ``(x, y, theta, v)``; ``u1`` in ``[-u1_max, u1_max]``, ``u2`` in ``[-u2_max, u2_max]``;
    bounded disturbance ``|d_x|, |d_y| <= d_max`` on the position rates (0 by default, as the
    paper ran); speed held in ``[v_min, v_max]`` as in the environment.

    The bounds are the dynamics object's, not written again here: the defaults are
    ``Dubins4D``'s, :meth:`from_dynamics` reads a ``Dubins4D`` instance and :meth:`from_bounds`
    the control bounds an action space carries.  The Hamiltonian below takes the control box
    symmetric about 0 (as Dubins4D's is); other boxes are refused.  The fields (and so the
    value cache's key) are unchanged from when the numbers were written here."""

    u1_max: float = Dubins4D.u1_max
    u2_max: float = Dubins4D.u2_max
    v_min: float = Dubins4D.v_min
    v_max: float = Dubins4D.v_max
    d_max: float = 0.0

    @classmethod
    def from_bounds(
        cls, control_low, control_high, v_min: float = Dubins4D.v_min, v_max: float = Dubins4D.v_max, d_max: float = 0.0
    ) -> Dubins4DHJ:
        """From control bounds ``(u1, u2)`` (an action space's ``control_low``/``control_high``),
        which must be symmetric about 0, and the speed bounds (default: Dubins4D's)."""
        lo = np.asarray(control_low, float).reshape(-1)
        hi = np.asarray(control_high, float).reshape(-1)
        if lo.shape != (2,) or hi.shape != (2,) or not np.all(hi > 0) or not np.array_equal(lo, -hi):
            raise ValueError(
                f"the HJ Dubins4D dynamics need two control bounds (u1, u2) symmetric about 0, "
                f"got low={lo.tolist()} high={hi.tolist()}"
            )
        return cls(u1_max=float(hi[0]), u2_max=float(hi[1]), v_min=float(v_min), v_max=float(v_max), d_max=float(d_max))

    @classmethod
    def from_dynamics(cls, dynamics: Dubins4D, d_max: float = 0.0) -> Dubins4DHJ:
        """From a :class:`Dubins4D` dynamics object: its control and speed bounds."""
        return cls.from_bounds(dynamics.control_low, dynamics.control_high, dynamics.v_min, dynamics.v_max, d_max)

    def key(self) -> dict:
        return {"name": "dubins4d", **self.__dict__}

    def hamiltonian(self, grid, p, control: str = "max"):
        """``control="max"``: the control avoids (maximises); ``"min"``: it reaches (minimises)."""
        th, v = grid.coord(2), grid.coord(3)
        vv = np.minimum(v, self.v_max).astype(np.float32)
        c, s = (np.cos(th) * vv).astype(np.float32), (np.sin(th) * vv).astype(np.float32)
        sign = 1.0 if control == "max" else -1.0
        H = p[0] * c
        H += p[1] * s
        H += sign * self.u1_max * np.abs(p[2])
        # speed: the extremum over u2 of p_v u2, except that u2 cannot push past a speed bound
        can_up = (v < self.v_max).astype(np.float32)
        can_down = (v > self.v_min).astype(np.float32)
        H += sign * self.u2_max * np.maximum(sign * p[3] * can_up, -sign * p[3] * can_down)
        if self.d_max:  # the disturbance opposes the control
            H -= sign * self.d_max * (np.abs(p[0]) + np.abs(p[1]))
        return H

    def alphas(self, grid):
        v = np.minimum(grid.axes[3], self.v_max).max()
        return [v + self.d_max, v + self.d_max, self.u1_max, self.u2_max]

    def optimal_control(self, x, grad, control: str = "max"):
        """Bang-bang control maximising (avoid) or minimising (reach) ``grad . f``."""
        s = 1.0 if control == "max" else -1.0
        u1 = self.u1_max if s * grad[2] >= 0 else -self.u1_max
        u2 = self.u2_max if s * grad[3] >= 0 else -self.u2_max
        return u1, u2


@dataclass(frozen=True)
class DoubleIntegrator1D:
    """``x' = v, v' = u, |u| <= a_max`` (for accuracy tests: braking toward a wall)."""

    a_max: float = 1.0

    def key(self) -> dict:
        return {"name": "double_integrator", **self.__dict__}

    def hamiltonian(self, grid, p):
        return p[0] * grid.coord(1).astype(np.float32) + self.a_max * np.abs(p[1])

    def alphas(self, grid):
        return [float(np.abs(grid.axes[1]).max()), self.a_max]


@dataclass(frozen=True)
class Integrator1D:
    """``x' = u, |u| <= u_max`` (for reach-avoid tests)."""

    u_max: float = 1.0

    def key(self) -> dict:
        return {"name": "integrator", **self.__dict__}

    def hamiltonian(self, grid, p, control: str = "max"):
        return (1.0 if control == "max" else -1.0) * self.u_max * np.abs(p[0])

    def alphas(self, grid):
        return [self.u_max]


@dataclass(frozen=True)
class Translation:
    """``x' = c`` (constant velocity in each axis; for tests)."""

    c: tuple = (1.0,)

    def key(self) -> dict:
        return {"name": "translation", "c": list(self.c)}

    def hamiltonian(self, grid, p):
        H = np.zeros_like(p[0])
        for pi, ci in zip(p, self.c, strict=True):
            H += ci * pi
        return H

    def alphas(self, grid):
        return [abs(c) for c in self.c]
