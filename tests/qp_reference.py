"""An exact dense QP reference: enumerate active sets and solve each KKT system.

For ``min 1/2 z'Pz + q'z  s.t.  G z <= h`` with P positive definite the optimum is unique; the
first active set whose KKT solution is primal feasible with non-negative multipliers is it.
Exponential in the number of constraints, exact, and independent of OSQP.
"""

from itertools import combinations

import numpy as np


def solve_qp_dense(P, q, G, h, tol=1e-9):
    P, q, G, h = (np.asarray(a, float) for a in (P, q, G, h))
    n, m = P.shape[0], G.shape[0]
    for k in range(0, min(n, m) + 1):
        for S in combinations(range(m), k):
            S = list(S)
            GS = G[S]
            K = np.block([[P, GS.T], [GS, np.zeros((k, k))]])
            rhs = np.concatenate([-q, h[S]])
            try:
                sol = np.linalg.solve(K, rhs)
            except np.linalg.LinAlgError:
                continue
            z, lam = sol[:n], sol[n:]
            if np.all(G @ z <= h + tol * (1 + np.abs(h))) and np.all(lam >= -tol):
                return z
    raise ValueError("infeasible QP")
