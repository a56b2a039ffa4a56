"""Which QP solver the CBF guardians use: OSQP directly (the default) or any solver of qpsolvers.

``solver="osqp"`` (the default) keeps the direct OSQP path: the problem is set up once per
episode with a fixed sparsity and each step only updates values and bounds, then re-solves
warm-started (:class:`rmm_guardians.cbf.qp.BarrierQP` for Dubins4D,
:class:`rmm_guardians.cbf.maze.WallQP` for the maze car).  ``solver="qpsolvers:<name>"`` hands the
same QP, as dense rows ``G z <= h`` and box bounds, to ``qpsolvers.solve_qp(..., solver=name)``
for any solver qpsolvers has installed (the optional extra ``rmm-envs[qp]``).  Any other name
is refused at the guardian's construction, with the installed solvers listed.

The direct path is the default because qpsolvers' front end rebuilds the problem on every call;
the tolerances: :class:`QpsolversQP`.
"""

from __future__ import annotations

import numpy as np

from rmm_guardians.cbf.qp import BarrierQP
from rmm_guardians.cbf.quiet import quietly

__all__ = ["DEFAULT_SOLVER", "QpsolversQP", "installed_solvers", "parse_solver"]

DEFAULT_SOLVER = "osqp"
PREFIX = "qpsolvers:"


def installed_solvers() -> list[str]:
    """The solvers qpsolvers can use here (empty when qpsolvers is not installed)."""
    try:  # lazy: qpsolvers is an optional dependency (the qp extra)
        import qpsolvers
    except ImportError:
        return []
    return sorted(qpsolvers.available_solvers)


def parse_solver(solver) -> str | None:
    """``None`` for the direct OSQP path (``"osqp"``), else the qpsolvers solver's name of
    ``"qpsolvers:<name>"``; a ``ValueError`` listing the choices for anything else."""
    if solver == DEFAULT_SOLVER:
        return None
    choices = [DEFAULT_SOLVER] + [PREFIX + n for n in installed_solvers()]
    if not isinstance(solver, str) or not solver.startswith(PREFIX):
        raise ValueError(f"solver must be 'osqp' (direct) or 'qpsolvers:<name>', got {solver!r}; installed: {choices}")
    name = solver[len(PREFIX) :]
    installed = installed_solvers()
    if not installed:
        raise ValueError(
            f"solver {solver!r} needs qpsolvers (the qp extra: pip install -e '.[qp]' in a clone); installed: {choices}"
        )
    if name not in installed:
        raise ValueError(f"solver {solver!r}: qpsolvers has no installed solver {name!r}; installed: {choices}")
    return name


def _options(name: str, eps: float, polish: bool = True) -> dict:
    if name == "osqp":
        return {"eps_abs": eps, "eps_rel": eps, "polishing": polish, "max_iter": 4000}
    return {}


class QpsolversQP:
    """``min z' P z / 2  s.t.  G z <= h, lb <= z <= ub`` through ``qpsolvers.solve_qp``.

    Args:
        P: the (fixed) dense cost matrix.
        name: an installed qpsolvers solver (see :func:`parse_solver`).
        eps: the guardian's ``eps`` (``1e-6``), passed on as OSQP's absolute and relative
            tolerance (solutions polished, as on the direct path); the other solvers run at their
            own defaults, tighter than ``1e-6`` (``clarabel``'s interior point 1e-8; ``daqp`` is a
            dense active-set method, exact up to rounding).  The decisions agree with the direct
            path to the solvers' tolerance (``tests/test_cbf_solvers.py``).
        lb, ub: fixed box bounds on ``z`` (``None``: none).
        polish: whether OSQP polishes its solutions (as the direct path it mirrors does).
    """

    def __init__(self, P, name: str, eps: float, lb=None, ub=None, polish: bool = True) -> None:
        import qpsolvers  # lazy: an optional dependency (the qp extra), checked by parse_solver
        from qpsolvers.exceptions import QPError

        self._solve_qp = qpsolvers.solve_qp
        self._errors = (QPError, ValueError, ArithmeticError)
        self.P = np.asarray(P, float)
        self.q = np.zeros(self.P.shape[0])
        self.name = name
        self.lb = None if lb is None else np.asarray(lb, float)
        self.ub = None if ub is None else np.asarray(ub, float)
        self.eps = eps
        self.options = _options(name, eps, polish)

    def solve(self, G, h) -> np.ndarray | None:
        """The solution for the rows ``(G, h)``; ``None`` if infeasible or the solver failed."""
        G, h = np.asarray(G, float), np.asarray(h, float)
        # a row with no variable in it (coefficients under 1e-12) is a fact about the state: infeasible below -eps (OSQP's
        # tolerance on the direct path), else it constrains nothing; some solvers call an empty
        # row with h = -1e-12 infeasible.  A row bounded by +inf constrains nothing either.
        empty = ~np.any(np.abs(G) > 1e-12, axis=1)
        if np.any(h[empty] < -self.eps):
            return None
        keep = np.isfinite(h) & ~empty
        if self.lb is not None and self.ub is not None:
            # a row that every point of the box satisfies (its largest value over the box is
            # within h) constrains nothing the bounds do not: left out, the same solution.  Such
            # rows can be scaled far from the others (the maze car heading along a wall: a
            # coefficient of 5e-8 beside ones of 50), which clarabel's equilibration cannot
            # handle: it stopped with InsufficientProgress on feasible QPs (tests/test_cbf_solvers.py)
            keep &= ~(np.maximum(G * self.lb, G * self.ub).sum(axis=1) <= h)
        try:
            z = quietly(
                self._solve_qp,
                self.P,
                self.q,
                G[keep],
                h[keep],
                lb=self.lb,
                ub=self.ub,
                solver=self.name,
                **self.options,
            )
        except self._errors:  # a solver that raises on an infeasible problem: no solution, as OSQP's status says
            return None
        if z is None or not np.all(np.isfinite(z)):
            return None
        return np.asarray(z, float)


class Dubins4DQpsolversQP:
    """The Dubins4D HOCBF-CLF QP (:class:`rmm_guardians.cbf.qp.BarrierQP`'s) through qpsolvers: the
    same ``solve(G, h)`` on the dense rows of :func:`rmm_guardians.cbf.barrier.barrier_rows`."""

    def __init__(self, K: int, p_theta: float, p_v: float, name: str, eps: float) -> None:
        self.K = K
        self._qp = QpsolversQP(np.diag([2.0, 2.0, 2.0 * p_theta, 2.0 * p_v]), name, eps)

    def solve(self, G, h, u_ref=None) -> np.ndarray | None:
        K = self.K
        h = np.array(h, float)
        self._qp.q[:] = 0.0
        if u_ref is not None:  # the safety filter: |u - u_ref|^2, no CLF rows (as BarrierQP)
            h[K + 4] = h[K + 5] = np.inf
            self._qp.q[:2] = -2.0 * np.asarray(u_ref, float)[:2]
        # the u2 box merged with the speed barriers: an empty interval (a speed outside its
        # range) becomes the point u2 = its upper end, as on the direct path
        if -h[K + 3] > h[K + 2]:
            h[K + 3] = -h[K + 2]
        return self._qp.solve(G, h)


def dubins4d_qp(solver: str, K: int, prm, p_theta: float, p_v: float, eps: float):
    """The Dubins4D guardian's QP for ``solver`` (checked by :func:`parse_solver`)."""
    name = parse_solver(solver)
    if name is None:
        return BarrierQP(K, prm, p_theta, p_v, eps)
    return Dubins4DQpsolversQP(K, p_theta, p_v, name, eps)
