import math

import numpy as np
import pytest

from rmm_envs.systems.dubins4d.driver import CLFDriver, desired_heading
from tests.qp_reference import solve_qp_dense


def test_acceptance_value():
    d = CLFDriver(u1_bounds=(-0.1, 0.1), u2_bounds=(-0.5, 0.5))
    np.testing.assert_allclose(d.solve(np.zeros(4), (5.0, 0.0)), [0.0, 0.025, 0.0, 0.05], atol=1e-4)


def _reference(state, goal, u1b=(-0.25, 0.25), u2b=(-0.5, 0.5)):
    """An exact dense solve of the same QP, built from the original's rows (unmerged; docs/original-code.md item 20)."""
    x, y, th, v = state
    xh, yh = goal[0] - x, goal[1] - y
    d2 = xh * xh + yh * yh
    vd = (math.sqrt(d2) / 10) ** 2
    th = (th + math.pi) % (2 * math.pi) - math.pi
    thd = desired_heading(th, math.atan2(yh, xh))
    e = th - thd
    lf = 2 * v * e * (xh * math.sin(th) - yh * math.cos(th)) / d2
    G = np.array(
        [
            [0, 1, 0, 0],
            [0, -1, 0, 0],
            [1, 0, 0, 0],
            [-1, 0, 0, 0],
            [0, 1, 0, 0],
            [0, -1, 0, 0],
            [2 * e, 0, -1, 0],
            [0, 2 * (v - vd), 0, -1],
        ],
        float,
    )
    h = np.array([2 - v, v, u1b[1], -u1b[0], u2b[1], -u2b[0], -lf - e * e, -((v - vd) ** 2)])
    return solve_qp_dense(2 * np.eye(4), np.zeros(4), G, h)


def test_agrees_with_an_independent_solver():
    rng = np.random.default_rng(0)
    d = CLFDriver()
    for _ in range(200):
        s = np.array([*rng.uniform(-10, 10, 2), rng.uniform(-np.pi, np.pi), rng.uniform(0, 2)])
        g = rng.uniform(-10, 10, 2)
        np.testing.assert_allclose(d.solve(s, g), _reference(s, g), atol=1e-4)


def test_driver_heads_to_the_goal():
    d = CLFDriver()
    u = d.control(np.array([0.0, 0.0, 0.0, 1.0]), (0.0, 5.0))  # goal to the left
    assert u[0] > 0
    u = d.control(np.array([0.0, 0.0, 0.0, 1.0]), (0.0, -5.0))
    assert u[0] < 0


def test_branch_cut_heuristic_literal():
    assert desired_heading(-0.5, math.pi - 0.2) == -1.5 * math.pi
    assert desired_heading(0.5, -math.pi + 0.2) == 1.5 * math.pi
    assert desired_heading(0.5, 1.0) == 1.0


def test_bad_bounds():
    with pytest.raises(ValueError, match="bounds"):
        CLFDriver(u1_bounds=(1, -1))


# ---------------------------------------------------------------------- the closed form
from hypothesis import assume, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from rmm_envs.systems.dubins4d.driver import DriverParams, clf_qp  # noqa: E402

_coord = st.floats(-12, 12)
_gain = st.floats(0.0, 5.0)
_weight = st.floats(0.05, 5.0)


@settings(max_examples=150, deadline=None)
@given(
    x=_coord,
    y=_coord,
    th=st.floats(-4, 4),
    v=st.floats(-0.5, 2.5),
    gx=_coord,
    gy=_coord,
    gains=st.tuples(_gain, _gain, _gain, _gain),
    weights=st.tuples(_weight, _weight),
    u1=st.floats(0.01, 1.0),
    u2=st.floats(0.01, 1.0),
)
@example(x=0.0, y=11.0, th=0.0, v=0.0, gx=0.0, gy=0.0, gains=(0.0, 0.0, 0.0, 1e-09), weights=(1.0, 1.0), u1=1.0, u2=1.0)
def test_closed_form_matches_osqp_and_the_dense_reference(x, y, th, v, gx, gy, gains, weights, u1, u2):
    """Random instances, speeds outside the bounds included: the closed form is OSQP's solution
    to 1e-6 and the exact active-set enumeration's to 3e-9 (relative to the solution's size).

    The goal is kept at least 1 um from the car: the heading CLF's row scales as 1 / distance^2,
    and past about 1e12 OSQP's own data validation fails (it returns zeros or controls outside
    the box), so it is no reference there; the closed form's answer stays in the box
    (``test_closed_form_at_a_coincident_goal``).  The env never gets there: reaching the goal
    (radius >= 0.1 m) ends the episode."""
    assume((gx - x) ** 2 + (gy - y) ** 2 >= 1e-12)
    p = DriverParams(*gains, *weights)
    s, g = np.array([x, y, th, v]), np.array([gx, gy])
    kw = dict(u1_bounds=(-u1, u1), u2_bounds=(-u2, u2), params=p)
    z = CLFDriver(**kw).solve(s, g)
    z_osqp = CLFDriver(**kw, solver="osqp").solve(s, g)
    scale = 1.0 + np.abs(z_osqp)
    assert np.all(np.abs(z - z_osqp) <= 1e-6 * scale), (z, z_osqp)
    # the dense reference: the same rows, unmerged (the u2 interval as the driver forms it)
    a1, b1, a2, b2, l2, h2 = _rows(s, g, u1, u2, p)
    G = np.array([[1, 0, 0, 0], [-1, 0, 0, 0], [0, 1, 0, 0], [0, -1, 0, 0], [a1, 0, -1, 0], [0, a2, 0, -1]], float)
    h = np.array([u1, u1, h2, -l2, b1, b2])
    ref = solve_qp_dense(np.diag([2, 2, 2 * p.p_theta, 2 * p.p_v]), np.zeros(4), G, h)
    # the reference accepts a vertex that breaks a row by up to 1e-9 (its feasibility tolerance), and
    # a slack then differs by a few times that: u2 in the one-point interval [0, 0] (gains 0) taken
    # as 5e-10 moved d_v by 1.25e-9 (found by hypothesis; pinned by the @example)
    assert np.all(np.abs(z - ref) <= 3e-9 * (1 + np.abs(ref))), (z, ref)


@pytest.mark.parametrize("eps", [0.0, 1e-30, 1e-44])
def test_closed_form_at_a_coincident_goal(eps):
    """A goal on top of the car (or 1e-44 m away, where the heading row reaches 1e42): the
    controls stay finite and in the box, only the CLF slack grows."""
    z = CLFDriver(u1_bounds=(-1, 1), u2_bounds=(-1, 1)).solve(
        np.array([0.0, 0.0, 0.5, 1.0]), np.array([eps, 0.3 * eps])
    )
    assert np.all(np.isfinite(z[:2])) and np.all(np.abs(z[:2]) <= 1.0) and z[2] >= 0 and z[3] >= 0


def _rows(s, g, u1, u2, p):
    """The QP's rows written out here from the formulas (independent of the driver's code)."""
    x, y, th, v = s
    xh, yh = g[0] - x, g[1] - y
    d2 = xh * xh + yh * yh
    th = (th + math.pi) % (2 * math.pi) - math.pi
    e = th - desired_heading(th, math.atan2(yh, xh))
    lf = 2 * v * e * (xh * math.sin(th) - yh * math.cos(th)) / d2 if d2 > 0 else 0.0
    ev = v - d2 / 100
    l2, h2 = max(-u2, -p.gamma_vmin * v), min(u2, p.gamma_vmax * (2 - v))
    if l2 > h2:
        l2 = h2 = 0.0
    return 2 * e, -lf - p.lambda_theta * e * e, 2 * ev, -p.lambda_v * ev * ev, l2, h2


def test_closed_form_hand_values():
    # heading error e = -pi/2 (goal straight left, at rest): u1 = p a b / (1 + p a^2) with
    # a = 2e = -pi, b = -e^2 (LfV = 0 at v = 0), clipped to 0.25; speed row: v_d = 0.25,
    # a2 = -0.5, b2 = -0.0625 -> u2 = 0.5 * 0.0625 / 1.25 = 0.025 and d_v = a2 u2 - b2 = 0.05
    z = CLFDriver().solve(np.array([0.0, 0.0, 0.0, 0.0]), (0.0, 5.0))
    e = -math.pi / 2
    assert z[0] == 0.25
    assert z[2] == pytest.approx(2 * e * 0.25 + e * e, abs=1e-15)
    np.testing.assert_allclose(z[[1, 3]], [0.025, 0.05], atol=1e-15)
    # 0.5 m/s above v_max the barrier asks u2 <= -0.5, exactly the box: u2 = -0.5; 1 m/s
    # above, u2 <= -1 leaves the box: the interval is empty and u2 is pinned to 0
    assert CLFDriver().solve(np.array([0.0, 0.0, 0.0, 2.5]), (5.0, 0.0))[1] == -0.5
    assert CLFDriver().solve(np.array([0.0, 0.0, 0.0, 3.0]), (5.0, 0.0))[1] == 0.0


def test_batch_equals_one_at_a_time_bit_for_bit():
    rng = np.random.default_rng(3)
    s = np.column_stack([rng.uniform(-10, 10, (64, 2)), rng.uniform(-np.pi, np.pi, 64), rng.uniform(0, 2, 64)])
    g = rng.uniform(-10, 10, (64, 2))
    d = CLFDriver()
    batch = d.solve_batch(s, g)
    one = np.array([d.solve(a, b) for a, b in zip(s, g, strict=True)])  # 64 states, 64 goals
    assert np.array_equal(batch, one)
    assert np.array_equal(d.controls(s, g), batch[:, :2])
    assert np.array_equal(clf_qp(s, g, d.lim, d.gain), batch)


def test_bad_solver_and_shapes():
    with pytest.raises(ValueError, match="solver must be one of"):
        CLFDriver(solver="cvxpy")
    with pytest.raises(ValueError, match=r"states must be \(N, 4\)"):
        clf_qp(np.zeros((3, 4)), np.zeros((2, 2)), CLFDriver().lim, CLFDriver().gain)


def test_env_driver_solver_option():
    """``driver_solver="osqp"`` (the earlier solver, kept for checking) drives the same
    episode as the closed form, to OSQP's tolerance; an unknown solver is refused."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    inactive = {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}
    a, b = gym.make("Dubins4DGuarded-v0"), gym.make("Dubins4DGuarded-v0", driver_solver="osqp")
    a.reset(seed=4)
    b.reset(seed=4)
    for _ in range(60):
        ra, rb = a.step(inactive), b.step(inactive)
        np.testing.assert_allclose(ra[4]["control"], rb[4]["control"], atol=1e-6)
        np.testing.assert_allclose(ra[4]["state"], rb[4]["state"], atol=1e-6)
        assert ra[1:4] == rb[1:4]
        if ra[2] or ra[3]:
            break
    with pytest.raises(ValueError, match="driver solver must be one of"):
        gym.make("Dubins4DGuarded-v0", driver_solver="qpoases")
