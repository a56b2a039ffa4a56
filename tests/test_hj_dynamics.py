"""The HJ dynamics contract in code (rmm_guardians.hj.dynamics.HJDynamics): every dynamics the project
ships satisfies it, its alphas bound the Hamiltonian's slope as the solver assumes, and the solver
refuses an object that does not offer it, naming what is missing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_guardians.hj.dynamics import (
    DoubleIntegrator1D,
    Dubins4DHJ,
    HJControlDynamics,
    HJDynamics,
    Integrator1D,
    Translation,
    check_dynamics,
)
from rmm_guardians.hj.grid import Grid
from rmm_guardians.hj.solver import solve_brt

GRIDS = {
    "dubins4d": Grid([-2.0, -2.0, -np.pi, 0.0], [2.0, 2.0, np.pi, 2.0], [5, 5, 8, 5], periodic=[2]),
    "2d": Grid([-1.0, -2.0], [1.0, 2.0], [7, 9]),
    "1d": Grid([-1.0], [1.0], [11]),
}
DYNAMICS = [
    (Dubins4DHJ(), "dubins4d"),
    (Dubins4DHJ(u1_max=0.1, u2_max=0.3, d_max=0.2), "dubins4d"),
    (DoubleIntegrator1D(a_max=0.5), "2d"),
    (Integrator1D(u_max=2.0), "1d"),
    (Translation((1.5, -0.5)), "2d"),
]


@pytest.mark.parametrize("dynamics, grid", DYNAMICS)
def test_every_shipped_dynamics_satisfies_the_contract(dynamics, grid):
    assert isinstance(dynamics, HJDynamics) and check_dynamics(dynamics) is dynamics
    key = dynamics.key()
    assert isinstance(key["name"], str) and key == type(dynamics)(**{k: v for k, v in vars(dynamics).items()}).key()
    g = GRIDS[grid]
    H = dynamics.hamiltonian(g, [np.ones(g.shape, np.float32)] * g.ndim)
    assert H.shape == g.shape and len(dynamics.alphas(g)) == g.ndim


def test_the_guardians_dynamics_also_give_the_optimal_control():
    d = Dubins4DHJ()
    assert isinstance(d, HJControlDynamics)
    assert not isinstance(Translation(), HJControlDynamics)
    assert d.optimal_control(None, [0.0, 0.0, 1.0, -1.0]) == (d.u1_max, -d.u2_max)
    assert d.optimal_control(None, [0.0, 0.0, 1.0, -1.0], control="min") == (-d.u1_max, d.u2_max)


@settings(max_examples=40, deadline=None)
@given(idx=st.integers(0, len(DYNAMICS) - 1), seed=st.integers(0, 2**32 - 1), step=st.floats(-2.0, 2.0))
def test_alphas_bound_the_slope_of_the_hamiltonian_in_each_costate(idx, seed, step):
    """``|H(p + h e_i) - H(p)| <= alpha_i |h|`` at every grid point: what the Lax-Friedrichs
    dissipation and the CFL step rely on."""
    dynamics, grid = DYNAMICS[idx]
    g = GRIDS[grid]
    rng = np.random.default_rng(seed)
    p = [rng.uniform(-3, 3, g.shape).astype(np.float32) for _ in range(g.ndim)]
    H0 = dynamics.hamiltonian(g, p).astype(float)
    for i, a in enumerate(dynamics.alphas(g)):
        q = list(p)
        q[i] = (p[i] + np.float32(step)).astype(np.float32)
        dH = np.abs(dynamics.hamiltonian(g, q).astype(float) - H0)
        assert np.all(dH <= np.max(a) * abs(step) * (1 + 1e-5) + 1e-5), (type(dynamics).__name__, i)


class NoAlphas:
    def key(self):
        return {"name": "no-alphas"}

    def hamiltonian(self, grid, p):
        return p[0]


def test_the_solver_refuses_dynamics_without_the_contract_naming_what_is_missing():
    g = GRIDS["1d"]
    assert not isinstance(NoAlphas(), HJDynamics)
    with pytest.raises(
        TypeError,
        match=r"HJ dynamics must offer key\(\), hamiltonian\(grid, p\) and alphas\(grid\).*"
        r"lacks alphas",
    ):
        solve_brt(g, NoAlphas(), np.zeros(g.shape, np.float32), 1.0)
    with pytest.raises(TypeError, match="lacks key, hamiltonian, alphas"):
        check_dynamics(object())
