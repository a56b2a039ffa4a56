"""High-order control barrier function (HOCBF) guardian, solved with OSQP.

Uses **privileged** information: the true state and the obstacles (from the env's documented
``privileged()`` accessor).  After Xiao & Belta's HOCBFs, as in the paper (REFERENCE 2.2).

For each circular obstacle ``i`` a relative-degree-2 barrier with inflation ``k`` (1.05)::

    b_i = (x - x_i)^2 + (y - y_i)^2 - (k r_i)^2
    Lf b = 2 v ((x - x_i) cos th + (y - y_i) sin th),   Lf^2 b = 2 v^2
    LgLf b = [2 v ((y - y_i) cos th - (x - x_i) sin th),  2 ((x - x_i) cos th + (y - y_i) sin th)]
    Lf^2 b + LgLf b . u + p1 Lf b + p2 (Lf b + p1 b) >= 0        (linear class-K, p1, p2)

with ``p1 = 0.7535, p2 = 0.6664`` (the paper's).  The QP over ``z = (u1, u2, d_th, d_v)``::

    minimise u1^2 + u2^2 + p_th d_th^2 + p_v d_v^2
    s.t. the barrier rows above (hard), the speed barriers and control box (merged into one
    row on u2, as in the driver), the heading CLF (as the driver's) and a speed CLF toward
    v_d = min((d/2)^2, d/2) with V_v = (v - v_d)^2.

The original wrote the speed CLF as ``(v - v_d) * 82`` (a typo for the square, REFERENCE P7);
we use the square.  The original also braked fully whenever ``v < 0.05`` (so a stopped car
never moved again); that is off by default (``low_speed_stop=True`` restores it).

Intervention: the guardian takes control, applying the QP's ``(u1, u2)``, when a barrier row
is active at the solution: ``|G_i z* - h_i| <= active_atol + active_rtol |h_i|`` (defaults
``1e-3`` and ``0``: equality up to the solver's polished accuracy; the original used a loose
0.1/0.1).  Otherwise the driver keeps control.

The problem is set up once per episode (fixed sparsity for the episode's obstacles) and each
step only updates values and bounds, then re-solves warm-started.  An infeasible or failed
QP is never silent: the guardian brakes at maximum, and counts it (``stats()["qp_fallbacks"]``).
A state with NaN also brakes, counted as ``nan_states``.  More than ``max_obstacles`` (64)
obstacles is refused at reset.
"""

from __future__ import annotations

import math

import numpy as np
import osqp
import scipy.sparse as sp

from guardians.base import Guardian, active_action, inactive_action
from rmm_envs.driver import desired_heading

__all__ = ["CBFGuardian"]


class CBFGuardian(Guardian):
    name = "cbf"
    observation_type = "global"
    privileged = True

    def __init__(self, p1: float = 0.7535, p2: float = 0.6664, inflation: float = 1.05,
                 gamma_vmin: float = 1.0, gamma_vmax: float = 1.0, lambda_theta: float = 1.0,
                 lambda_v: float = 1.0, p_theta: float = 1.0, p_v: float = 1.0,
                 u1_bounds=(-0.25, 0.25), u2_bounds=(-0.5, 0.5), v_bounds=(0.0, 2.0),
                 active_atol: float = 1e-3, active_rtol: float = 0.0, low_speed_stop: bool = False,
                 max_obstacles: int = 64, eps: float = 1e-6) -> None:
        super().__init__()
        if not (p1 > 0 and p2 > 0):
            raise ValueError(f"class-K gains p1, p2 must be > 0, got {p1}, {p2}")
        if not inflation >= 1:
            raise ValueError(f"inflation must be >= 1, got {inflation}")
        self.p1, self.p2, self.k = float(p1), float(p2), float(inflation)
        self.gamma_vmin, self.gamma_vmax = gamma_vmin, gamma_vmax
        self.lambda_theta, self.lambda_v = lambda_theta, lambda_v
        self.p_theta, self.p_v = p_theta, p_v
        self.u1_min, self.u1_max = map(float, u1_bounds)
        self.u2_min, self.u2_max = map(float, u2_bounds)
        self.v_min, self.v_max = map(float, v_bounds)
        self.active_atol, self.active_rtol = float(active_atol), float(active_rtol)
        self.low_speed_stop = bool(low_speed_stop)
        self.max_obstacles = int(max_obstacles)
        self.eps = eps
        self._solver = None
        self._counts = {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0}

    # ------------------------------------------------------------------ setup
    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        priv = self._privileged()
        obstacles = np.asarray(priv["obstacles"], float).reshape(-1, 3)
        if obstacles.shape[0] > self.max_obstacles:
            raise ValueError(f"{obstacles.shape[0]} obstacles exceed this CBF guardian's QP limit of {self.max_obstacles}")
        self.obstacles = obstacles
        self.goal = np.asarray(priv["goal"], float)
        self._counts = {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0}
        K = obstacles.shape[0]
        self.K = K
        # rows: 0..K-1 barriers (u1, u2); K u1 box; K+1 u2 box+speed; K+2 heading CLF (u1, d_th); K+3 speed CLF (u2, d_v)
        m = K + 4
        rows = [np.r_[np.arange(K), K, K + 2], np.r_[np.arange(K), K + 1, K + 3], [K + 2], [K + 3]]
        self._indices = np.concatenate(rows).astype(np.int32)
        self._indptr = np.cumsum([0] + [len(r) for r in rows]).astype(np.int32)
        self._Ax = np.ones(self._indices.shape[0])
        self._Ax[self._indptr[2]] = -1.0  # d_th in the heading CLF
        self._Ax[self._indptr[3]] = -1.0  # d_v in the speed CLF
        A = sp.csc_matrix((self._Ax.copy(), self._indices, self._indptr), shape=(m, 4))
        P = sp.diags([2.0, 2.0, 2.0 * self.p_theta, 2.0 * self.p_v], format="csc")
        self._l = np.full(m, -np.inf)
        self._u = np.full(m, np.inf)
        self._l[K], self._u[K] = self.u1_min, self.u1_max
        self._l[K + 1], self._u[K + 1] = self.u2_min, self.u2_max
        self._u[K + 2] = self._u[K + 3] = 0.0
        self._solver = osqp.OSQP()
        self._solver.setup(P, np.zeros(4), A, self._l, self._u, verbose=False, eps_abs=self.eps, eps_rel=self.eps,
                           polishing=True, warm_starting=True, max_iter=4000)
        self._m = m

    # ------------------------------------------------------------------ the QP
    def rows(self, state):
        """Dense ``(G, h)`` of ``G z <= h`` at ``state`` (the same rows the OSQP problem holds),
        plus the barrier values; for tests against independent solvers."""
        x, y, th, v = (float(s) for s in state[:4])
        ox, oy, r = self.obstacles[:, 0], self.obstacles[:, 1], self.obstacles[:, 2]
        dx, dy = x - ox, y - oy
        c, s = math.cos(th), math.sin(th)
        b = dx * dx + dy * dy - (self.k * r) ** 2
        lfb = 2.0 * v * (dx * c + dy * s)
        lf2b = 2.0 * v * v
        g1 = 2.0 * v * (dy * c - dx * s)
        g2 = 2.0 * (dx * c + dy * s)
        h_bar = lf2b + self.p1 * lfb + self.p2 * (lfb + self.p1 * b)
        K = self.K
        G = np.zeros((K + 6, 4))
        h = np.zeros(K + 6)
        G[:K, 0], G[:K, 1], h[:K] = -g1, -g2, h_bar
        # u1 box, u2 box merged with the speed barriers (as two rows each for a dense solver)
        G[K, 0], h[K] = 1.0, self.u1_max
        G[K + 1, 0], h[K + 1] = -1.0, -self.u1_min
        G[K + 2, 1], h[K + 2] = 1.0, min(self.u2_max, self.gamma_vmax * (self.v_max - v))
        G[K + 3, 1], h[K + 3] = -1.0, -max(self.u2_min, -self.gamma_vmin * (v - self.v_min))
        xh, yh = self.goal[0] - x, self.goal[1] - y
        d2 = xh * xh + yh * yh
        d = math.sqrt(d2)
        thw = (th + math.pi) % (2 * math.pi) - math.pi
        e = thw - desired_heading(thw, math.atan2(yh, xh))
        lfv = 2.0 * v * e * (xh * math.sin(thw) - yh * math.cos(thw)) / d2 if d2 > 0 else 0.0
        G[K + 4, 0], G[K + 4, 2], h[K + 4] = 2.0 * e, -1.0, -lfv - self.lambda_theta * e * e
        v_d = min((d / 2.0) ** 2, d / 2.0)
        ev = v - v_d
        G[K + 5, 1], G[K + 5, 3], h[K + 5] = 2.0 * ev, -1.0, -self.lambda_v * ev * ev
        return G, h

    def solve(self, state):
        """OSQP solution ``z*`` at ``state`` and the barrier rows' ``(G z*, h)``; None if it failed."""
        G, h = self.rows(state)
        K = self.K
        Ax = self._Ax
        p = self._indptr
        Ax[p[0]:p[0] + K] = G[:K, 0]
        Ax[p[0] + K + 1] = G[K + 4, 0]  # heading CLF coefficient of u1
        Ax[p[1]:p[1] + K] = G[:K, 1]
        Ax[p[1] + K + 1] = G[K + 5, 1]  # speed CLF coefficient of u2
        u = self._u
        u[:K] = h[:K]
        self._l[K + 1], u[K + 1] = -h[K + 3], h[K + 2]
        if self._l[K + 1] > u[K + 1]:
            self._l[K + 1] = u[K + 1]
        u[K + 2], u[K + 3] = h[K + 4], h[K + 5]
        self._solver.update(Ax=Ax, l=self._l, u=u)
        res = self._solver.solve(raise_error=False)
        self._counts["qp_solves"] += 1
        if res.info.status_val not in (1, 2) or res.x is None or not np.all(np.isfinite(res.x)):
            return None, G, h
        return np.asarray(res.x), G, h

    # ------------------------------------------------------------------ decision
    def act(self, observation, info=None):
        state = np.asarray(self._privileged()["state"], float)
        if not np.all(np.isfinite(state)):
            self._counts["nan_states"] += 1
            return active_action(0.0, self.u2_min)
        if self.low_speed_stop and state[3] < 0.05:
            return active_action(0.0, self.u2_min)
        if self.K == 0:
            return inactive_action()
        z, G, h = self.solve(state)
        if z is None:
            self._counts["qp_fallbacks"] += 1
            return active_action(0.0, self.u2_min)
        gap = h[: self.K] - G[: self.K] @ z
        if np.any(np.abs(gap) <= self.active_atol + self.active_rtol * np.abs(h[: self.K])):
            return active_action(float(np.clip(z[0], self.u1_min, self.u1_max)), float(np.clip(z[1], self.u2_min, self.u2_max)))
        return inactive_action()

    def stats(self) -> dict:
        return dict(self._counts)
