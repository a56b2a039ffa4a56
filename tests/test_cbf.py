import numpy as np
import pytest

from guardians.cbf import CBFGuardian
from tests.qp_reference import solve_qp_dense


def make(state, obstacles, goal=(20.0, 0.0, 0.5), **kw):
    g = CBFGuardian(**kw)
    box = {"state": np.asarray(state, float), "obstacles": np.asarray(obstacles, float), "goal": np.asarray(goal, float)}
    g.reset(seed=0, privileged=lambda: box)
    return g, box


def test_reference_worked_example():
    # REFERENCE 2.2: state (0,0,0,1), obstacle (3,0,1): b = 7.8975, Lf b = -6, row [0, 6], h = -2.55381
    g, _ = make([0, 0, 0, 1.0], [[3.0, 0.0, 1.0]])
    G, h = g.rows(np.array([0, 0, 0, 1.0]))
    np.testing.assert_allclose(G[0], [0.0, 6.0, 0.0, 0.0], atol=1e-12)
    assert h[0] == pytest.approx(-2.55381, abs=1e-5)
    assert h[0] / G[0, 1] == pytest.approx(-0.42563, abs=1e-5)


def test_takes_control_when_the_barrier_is_active():
    g, _ = make([0, 0, 0, 1.0], [[3.0, 0.0, 1.0]])
    a = g.act(None, {})
    assert a["active_ctrl"] == 1
    assert a["accel_ctrl"][0] == pytest.approx(-0.42563, abs=1e-3)


def test_driver_keeps_control_far_from_obstacles():
    g, _ = make([0, 0, 0, 1.0], [[30.0, 30.0, 1.0]])
    assert g.act(None, {})["active_ctrl"] == 0


def test_agrees_with_an_independent_dense_solver():
    rng = np.random.default_rng(0)
    for trial in range(150):
        obstacles = np.c_[rng.uniform(-10, 10, (5, 2)), rng.uniform(2, 5, 5)]
        while True:
            s = np.array([*rng.uniform(-10, 10, 2), rng.uniform(-np.pi, np.pi), rng.uniform(0, 2)])
            if np.all(np.hypot(s[0] - obstacles[:, 0], s[1] - obstacles[:, 1]) > 1.05 * obstacles[:, 2]):
                break
        g, box = make(s, obstacles, goal=(*rng.uniform(-10, 10, 2), 0.5))
        z, G, h = g.solve(s)
        try:
            ref = solve_qp_dense(np.diag([2.0, 2.0, 2.0, 2.0]), np.zeros(4), G, h)
        except ValueError:
            assert z is None, f"trial {trial}: OSQP solved an infeasible QP"
            continue
        assert z is not None, f"trial {trial}: OSQP failed on a feasible QP"
        np.testing.assert_allclose(z, ref, atol=1e-4)


def test_infeasible_qp_brakes_and_is_counted():
    # 0.5 m from the inflated... 1.5 m gap at 2 m/s: the barrier needs u2 <= -0.72, beyond the box
    g, _ = make([0, 0, 0, 2.0], [[2.5, 0.0, 1.0]])
    a = g.act(None, {})
    assert a["active_ctrl"] == 1 and a["accel_ctrl"][0] == -0.5 and a["turnrate_ctrl"][0] == 0.0
    assert g.stats()["qp_fallbacks"] == 1


def test_nan_state_brakes_and_is_counted():
    g, box = make([0, 0, 0, 1.0], [[30.0, 30.0, 1.0]])
    box["state"] = np.array([np.nan, 0, 0, 1.0])
    a = g.act(None, {})
    assert a["active_ctrl"] == 1 and a["accel_ctrl"][0] == -0.5
    assert g.stats()["nan_states"] == 1


def test_low_speed_stop_option_reproduces_the_original():
    g, _ = make([0, 0, 0, 0.01], [[30.0, 30.0, 1.0]], low_speed_stop=True)
    assert g.act(None, {})["active_ctrl"] == 1
    g, _ = make([0, 0, 0, 0.01], [[30.0, 30.0, 1.0]])
    assert g.act(None, {})["active_ctrl"] == 0


def test_configuration_errors_at_reset():
    with pytest.raises(ValueError, match="QP limit"):
        make([0, 0, 0, 1.0], np.c_[np.arange(70) * 10.0 + 100, np.zeros(70), np.ones(70)])
    with pytest.raises(ValueError, match="privileged"):
        CBFGuardian().reset(seed=0)
    with pytest.raises(ValueError, match="p1"):
        CBFGuardian(p1=0)
    with pytest.raises(ValueError, match="inflation"):
        CBFGuardian(inflation=0.9)
