"""The HOCBF quadratic programme, solved with OSQP: set up once per episode, updated per step.

Over ``z = (u1, u2, d_th, d_v)``: minimise ``u1^2 + u2^2 + p_th d_th^2 + p_v d_v^2`` subject to
the rows of :func:`rmm_guardians.cbf.barrier.barrier_rows` (the paper's CBF-CLF problem), or, given
a reference control ``u_ref`` (the driver's nominal control), the safety filter
``|u - u_ref|^2`` subject to the same rows without the two CLF rows (their coefficients set to
0 and their bounds to infinity, so the sparsity stays fixed; the slacks then settle at 0).  The sparse constraint matrix has one
row per obstacle and four more (``u1`` box; ``u2`` box merged with the speed barriers, as one
two-sided row; heading CLF; speed CLF), so its sparsity is fixed for the episode's obstacles:
each step only updates values and bounds, then re-solves warm-started.
"""

from __future__ import annotations

import math

import numpy as np
import osqp
import scipy.sparse as sp

from rmm_guardians.cbf.barrier import HOCBFParams
from rmm_guardians.cbf.quiet import quietly

__all__ = ["BarrierQP"]

#: OSQP's status values for "solved" and "solved inaccurate".
_SOLVED = (1, 2)
#: OSQP's status value for "maximum iterations reached".  Rarely (4 of 12,608 solves over 40
#: fixed-clock episodes of ``cbf-paper``, none of 9,312 for ``cbf``), near the edge of
#: feasibility, ADMM drives its step size to its upper limit and stops at ``max_iter`` on a
#: problem that is feasible (an active-set solver solves it).  The guardian then treats the QP
#: as unsolved, like an infeasible one (its fallback, counted as ``qp_fallbacks``).
MAX_ITER = 7
#: What the compiled solver object must offer for the direct path (osqp >= 1.0).
_NATIVE_API = ("update_data_vec", "update_data_mat", "solve", "info", "solution")


class BarrierQP:
    """The OSQP problem for ``K`` obstacles.

    Args:
        K: number of obstacles (barrier rows).
        prm: the rows' gains and bounds (the control box enters the bounds of the box rows).
        p_theta, p_v: weights of the heading and speed CLF slacks.
        eps: OSQP's absolute and relative tolerance (solutions polished).
    """

    def __init__(self, K: int, prm: HOCBFParams, p_theta: float, p_v: float, eps: float) -> None:
        self.K = K
        self.last_status = None  # OSQP's status value of the last solve (1 solved, 3 infeasible, MAX_ITER, ...)
        # rows: 0..K-1 barriers (u1, u2); K u1 box; K+1 u2 box+speed; K+2 heading CLF (u1, d_th); K+3 speed CLF (u2, d_v)
        m = K + 4
        rows = [np.r_[np.arange(K), K, K + 2], np.r_[np.arange(K), K + 1, K + 3], [K + 2], [K + 3]]
        self._indices = np.concatenate(rows).astype(np.int32)
        self._indptr = np.cumsum([0] + [len(r) for r in rows]).astype(np.int32)
        self._p0, self._p1 = int(self._indptr[0]), int(self._indptr[1])
        self._Ax = np.ones(self._indices.shape[0])
        self._Ax[self._indptr[2]] = -1.0  # d_th in the heading CLF
        self._Ax[self._indptr[3]] = -1.0  # d_v in the speed CLF
        A = sp.csc_matrix((self._Ax.copy(), self._indices, self._indptr), shape=(m, 4))
        P = sp.diags([2.0, 2.0, 2.0 * p_theta, 2.0 * p_v], format="csc")
        self._l = np.full(m, -np.inf)
        self._u = np.full(m, np.inf)
        self._l[K], self._u[K] = prm.u1_min, prm.u1_max
        self._l[K + 1], self._u[K + 1] = prm.u2_min, prm.u2_max
        self._u[K + 2] = self._u[K + 3] = 0.0
        self._q = np.zeros(4)
        self._solver = osqp.OSQP()
        self._solver.setup(
            P,
            self._q.copy(),
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
        # Per step, talk to the compiled solver object directly when the wrapper exposes it:
        # the Python wrapper's ``update``/``solve`` spend longer on bookkeeping (bound
        # clipping, derivative caches, a namespace of every info field) than OSQP spends
        # solving this 4-variable problem.  The same calls with the same data: the bounds are
        # clipped to OSQP's infinity here once, as the wrapper clips them on every update.
        inf = float(self._solver.constant("OSQP_INFTY"))
        self._inf = inf
        np.clip(self._l, -inf, inf, out=self._l)
        np.clip(self._u, -inf, inf, out=self._u)
        native = getattr(self._solver, "_solver", None)
        self._native = native if all(hasattr(native, a) for a in _NATIVE_API) else None

    def solve(self, G: np.ndarray, h: np.ndarray, u_ref=None) -> np.ndarray | None:
        """The solution ``z*`` for the dense rows ``(G, h)`` of the current state; ``None`` if the
        problem is infeasible or the solver failed.  ``u_ref``: filter this control (module
        docstring); ``None``: the CBF-CLF problem."""
        Ax, lower, upper = self._Ax, self._l, self._u
        _fill(Ax, lower, upper, G, h, self.K, self._p0, self._p1)
        q = None
        if u_ref is not None:
            K = self.K
            Ax[self._p0 + K + 1] = Ax[self._p1 + K + 1] = 0.0  # no CLF rows: the reference leads
            upper[K + 2] = upper[K + 3] = self._inf
            q = self._q
            q[0], q[1] = -2.0 * float(u_ref[0]), -2.0 * float(u_ref[1])
        native = self._native
        if native is not None:
            native.update_data_vec(q=q, l=lower, u=upper)
            native.update_data_mat(P_x=None, P_i=None, A_x=Ax, A_i=None)
            quietly(native.solve)
            status, x = native.info.status_val, native.solution.x
        else:
            self._solver.update(Ax=Ax, l=lower, u=upper, **({} if q is None else {"q": q}))
            res = quietly(self._solver.solve, raise_error=False)
            status, x = res.info.status_val, res.x
        self.last_status = status
        if status not in _SOLVED or x is None:
            return None
        x = np.asarray(x, dtype=float)
        if not all(map(math.isfinite, x.tolist())):
            return None
        return x


def _fill(Ax, lower, upper, G, h, K, p0, p1):
    """Copy the dense rows ``(G, h)`` into the sparse problem's values ``Ax`` (columns ``u1``
    from ``p0``, ``u2`` from ``p1``) and bounds ``lower, upper`` (rows as in :class:`BarrierQP`)."""
    for i in range(K):
        Ax[p0 + i] = G[i, 0]
        Ax[p1 + i] = G[i, 1]
        upper[i] = h[i]
    Ax[p0 + K + 1] = G[K + 4, 0]  # heading CLF coefficient of u1
    Ax[p1 + K + 1] = G[K + 5, 1]  # speed CLF coefficient of u2
    lower[K + 1], upper[K + 1] = -h[K + 3], h[K + 2]  # u2 box merged with the speed barriers
    if lower[K + 1] > upper[K + 1]:
        lower[K + 1] = upper[K + 1]
    upper[K + 2], upper[K + 3] = h[K + 4], h[K + 5]


try:
    from numba import njit

    _fill = njit(cache=True)(_fill)
except ImportError:  # pragma: no cover - numba is a dependency; the Python loop still works
    pass
