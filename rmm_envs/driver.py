"""The "reckless driver": a CLF-QP that steers to the goal and ignores obstacles.

From Xiao & Belta (high-order CBFs, Sec. V.B) as used by the paper's environment (REFERENCE
section 1.6).  Decision variable ``z = (u1, u2, d_theta, d_v)`` (controls and two CLF slacks)::

    minimise   u1^2 + u2^2 + p_theta d_theta^2 + p_v d_v^2
    subject to u2 <= gamma_vmax (v_max - v)                    (speed-max barrier)
               -u2 <= gamma_vmin (v - v_min)                   (speed-min barrier)
               u1_min <= u1 <= u1_max,  u2_min <= u2 <= u2_max (control box)
               2 (theta - theta_d) u1 - d_theta <= -LfV_theta - lambda_theta V_theta   (heading CLF)
               2 (v - v_d) u2 - d_v <= -lambda_v V_v                                (speed CLF)

with ``V_theta = (theta - theta_d)^2``, ``theta_d = atan2(goal - position)`` (plus the original's
literal +-1.5 pi heuristic near the branch cut), ``LfV_theta = 2 v (theta - theta_d)
(xh sin theta - yh cos theta) / d^2``, ``v_d = (d / 10)^2`` (unclipped) and ``V_v = (v - v_d)^2``.

Solved with OSQP: the problem is set up once with a fixed sparsity pattern and each call only
updates the constraint matrix values and bounds (``update(Ax=..., l=..., u=...)``) and re-solves,
warm-started from the previous solution.  :meth:`CLFDriver.reset` (called by the environment at
every episode start) sets the problem up afresh, so warm starts never cross episodes and an
episode's floats depend only on its own seed, whatever ran before it in the same process.  Rows 1-2 and the ``u2`` box are merged into one row
with the tighter bounds (an equivalent feasible set, one row fewer).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import osqp
import scipy.sparse as sp

__all__ = ["CLFDriver", "DriverParams"]


@dataclass(frozen=True)
class DriverParams:
    gamma_vmin: float = 1.0
    gamma_vmax: float = 1.0
    lambda_theta: float = 1.0
    lambda_v: float = 1.0
    p_theta: float = 1.0
    p_v: float = 1.0

    def __post_init__(self) -> None:
        # A NaN or infinite gain would silently turn a constraint off (or make the QP fail);
        # slack weights must be > 0 for the QP to stay strictly convex.
        for name in ("gamma_vmin", "gamma_vmax", "lambda_theta", "lambda_v", "p_theta", "p_v"):
            v = getattr(self, name)
            positive = name.startswith("p_")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v > 0 if positive else v >= 0)):
                raise ValueError(f"driver parameter {name} must be a finite number {'> 0' if positive else '>= 0'}, got {v!r}")


def desired_heading(theta: float, theta_goal: float) -> float:
    """The original's literal branch-cut heuristic for the target heading (REFERENCE 1.6)."""
    if -math.pi < theta < 0 and math.pi + theta <= theta_goal <= math.pi:
        return -1.5 * math.pi
    if 0 < theta < math.pi and -math.pi <= theta_goal <= -math.pi + theta:
        return 1.5 * math.pi
    return theta_goal


class CLFDriver:
    """Goal-seeking CLF-QP controller solved with a persistent OSQP problem.

    Args:
        u1_bounds, u2_bounds: control box.
        v_bounds: speed bounds used by the barrier rows.
        params: CLF/barrier gains and slack weights.
        eps: OSQP absolute and relative tolerance (solutions are also polished).
    """

    def __init__(
        self,
        u1_bounds=(-0.25, 0.25),
        u2_bounds=(-0.5, 0.5),
        v_bounds=(0.0, 2.0),
        params: DriverParams = DriverParams(),
        eps: float = 1e-7,
    ) -> None:
        self.u1_min, self.u1_max = map(float, u1_bounds)
        self.u2_min, self.u2_max = map(float, u2_bounds)
        self.v_min, self.v_max = map(float, v_bounds)
        if self.u1_min > self.u1_max or self.u2_min > self.u2_max:
            raise ValueError(f"control bounds must satisfy min <= max, got {u1_bounds}, {u2_bounds}")
        self.params = params
        self._eps = float(eps)
        self._P = sp.diags([2.0, 2.0, 2.0 * params.p_theta, 2.0 * params.p_v], format="csc")
        # Rows: 0 u1 box; 1 u2 box merged with the speed barriers; 2 heading CLF; 3 speed CLF.
        # Fixed pattern (column-major): col0 rows (0, 2); col1 rows (1, 3); col2 row 2; col3 row 3.
        self._A_indices = np.array([0, 2, 1, 3, 2, 3], dtype=np.int32)
        self._A_indptr = np.array([0, 2, 4, 5, 6], dtype=np.int32)
        self._A0 = np.array([1.0, 1.0, 1.0, 1.0, -1.0, -1.0])
        self.reset()

    def reset(self) -> None:
        """Forget everything earlier solves left behind: a fresh OSQP problem.

        OSQP keeps the last primal and dual iterates (the warm start) and its adapted step
        size ``rho`` between solves, so without this an episode's controls would depend, in
        the last bits, on the episodes the same driver solved before.  The environment calls
        it at every ``reset()``: an episode's result then depends only on its own seed.
        """
        A = sp.csc_matrix((self._A0.copy(), self._A_indices, self._A_indptr), shape=(4, 4))
        self._Ax = self._A0.copy()
        self._l = np.array([self.u1_min, self.u2_min, -np.inf, -np.inf])
        self._u = np.array([self.u1_max, self.u2_max, 0.0, 0.0])
        self._solver = osqp.OSQP()
        self._solver.setup(
            self._P, np.zeros(4), A, self._l, self._u,
            verbose=False, eps_abs=self._eps, eps_rel=self._eps, polishing=True, warm_starting=True,
            max_iter=4000,
        )

    def solve(self, state, goal_xy) -> np.ndarray:
        """Return the QP's solution ``z = (u1, u2, d_theta, d_v)`` at ``state = (x, y, theta, v)``."""
        x, y, theta, v = (float(s) for s in state[:4])
        gx, gy = float(goal_xy[0]), float(goal_xy[1])
        p = self.params
        xh, yh = gx - x, gy - y
        d2 = xh * xh + yh * yh
        d = math.sqrt(d2)
        v_d = (d / 10.0) ** 2
        th = (theta + math.pi) % (2.0 * math.pi) - math.pi
        th_d = desired_heading(th, math.atan2(yh, xh))
        e = th - th_d
        V_th = e * e
        LfV_th = 2.0 * v * e * (xh * math.sin(th) - yh * math.cos(th)) / d2 if d2 > 0 else 0.0
        ev = v - v_d
        V_v = ev * ev

        Ax = self._Ax
        Ax[1] = 2.0 * e  # col0,row2: heading CLF coefficient of u1
        Ax[3] = 2.0 * ev  # col1,row3: speed CLF coefficient of u2
        l, u = self._l, self._u
        l[1] = max(self.u2_min, -p.gamma_vmin * (v - self.v_min))
        u[1] = min(self.u2_max, p.gamma_vmax * (self.v_max - v))
        if l[1] > u[1]:  # speed outside its bounds: keep the problem feasible, favour the barrier
            l[1] = u[1] = min(max(0.0, self.u2_min), self.u2_max)
        u[2] = -LfV_th - p.lambda_theta * V_th
        u[3] = -p.lambda_v * V_v
        self._solver.update(Ax=Ax, l=l, u=u)
        res = self._solver.solve(raise_error=False)
        z = res.x
        if z is None or not np.all(np.isfinite(z)):
            raise RuntimeError(f"driver QP failed ({res.info.status}) at state {state[:4]}")
        return np.asarray(z, dtype=float)

    def control(self, state, goal_xy) -> np.ndarray:
        """The driver's ``(u1, u2)``, clipped to the control box."""
        z = self.solve(state, goal_xy)
        return np.array(
            [min(max(z[0], self.u1_min), self.u1_max), min(max(z[1], self.u2_min), self.u2_max)]
        )
