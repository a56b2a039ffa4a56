"""What the reckless drivers promise, as properties: the Dubins4D CLF-QP driver
(``rmm_envs/systems/dubins4d/driver.py``) keeps every barrier row it claims and reads the heading modulo a turn;
the maze's pursuit driver (``rmm_envs/systems/maze/driver.py``) turns the short way to its target.

Every Dubins4D result depends on the closed-form driver; its numbers feed the env only, so a
wrong bound would pass any test that only runs an episode.  These tests read the numbers."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.dubins4d.driver import CLFDriver, DriverParams, clf_qp
from rmm_envs.systems.maze.driver import PursuitDriver

finite = dict(allow_nan=False, allow_infinity=False)
coord = st.floats(-20.0, 20.0, **finite)
heading = st.floats(-math.pi, math.pi, **finite)
speed = st.floats(-0.5, 2.5, **finite)  # also outside [v_min, v_max] = [0, 2]
gain = st.floats(0.0, 3.0, **finite)
weight = st.floats(0.05, 20.0, **finite)
bound = st.floats(0.01, 1.0, **finite)


def _one(state, goal, lim, gain_vec):
    return clf_qp(np.array([state], float), np.array([goal], float), lim, gain_vec)[0]


@settings(max_examples=150, deadline=None)
@given(
    x=coord,
    y=coord,
    th=heading,
    v=speed,
    gx=coord,
    gy=coord,
    g=st.tuples(gain, gain, gain, gain),
    w=st.tuples(weight, weight),
    b=st.tuples(bound, bound, bound, bound),
    v_hi=st.floats(0.5, 3.0, **finite),
)
def test_every_barrier_row_and_the_box_hold_at_the_solution(x, y, th, v, gx, gy, g, w, b, v_hi):
    """The speed barriers ``u2 <= gamma_vmax (v_max - v)``, ``-u2 <= gamma_vmin (v - v_min)`` and the
    control box hold at the closed form's solution whenever they can hold together; when they
    cannot (speed outside its bounds) ``u2`` is the documented point ``clip(0, u2_min, u2_max)``.
    The CLF rows hold with their slacks, and the slacks are the least that makes them hold."""
    lim = np.array([-b[0], b[1], -b[2], b[3], 0.0, v_hi])
    gv = np.array([*g, *w])
    u1, u2, d_th, d_v = _one([x, y, th, v], [gx, gy], lim, gv)
    assert lim[0] <= u1 <= lim[1]
    lo2 = max(lim[2], -g[0] * (v - lim[4]))
    hi2 = min(lim[3], g[1] * (lim[5] - v))
    if lo2 <= hi2:
        assert lo2 - 1e-12 <= u2 <= hi2 + 1e-12
        assert u2 <= g[1] * (v_hi - v) + 1e-12 and -u2 <= g[0] * (v - 0.0) + 1e-12
    else:
        assert u2 == min(max(0.0, lim[2]), lim[3])
    # the CLF rows a u - d <= b, rebuilt from the docstring's formulas, hold with d = max(0, a u - b)
    xh, yh = gx - x, gy - y
    d2 = xh * xh + yh * yh
    vd = (math.sqrt(d2) / 10.0) ** 2
    assert d_v >= 0 and d_th >= 0
    a2, b2 = 2 * (v - vd), -g[3] * (v - vd) ** 2
    assert d_v == pytest.approx(max(0.0, a2 * u2 - b2), abs=1e-9)


def _near_a_branch_edge(th: float, gx: float, gy: float, x: float, y: float) -> bool:
    """Within a hair of an edge of the original's branch-cut heuristic, where a last-bit change of
    the wrapped heading may pick the other (equally literal) target heading."""
    b = math.atan2(gy - y, gx - x)
    edges = (0.0, math.pi, -math.pi, b - math.pi, b + math.pi)
    return any(abs(th - e) < 1e-6 for e in edges) or abs(abs(b) - math.pi) < 1e-6


@settings(max_examples=100, deadline=None)
@given(x=coord, y=coord, th=heading, v=st.floats(0.0, 2.0, **finite), gx=coord, gy=coord, k=st.integers(-3, 3))
def test_heading_is_read_modulo_a_full_turn(x, y, th, v, gx, gy, k):
    """A heading and the same heading plus ``k`` full turns are the same car: the same controls
    (the driver wraps theta to [-pi, pi) before it compares it with the goal's bearing)."""
    if _near_a_branch_edge(th, gx, gy, x, y) or math.hypot(gx - x, gy - y) < 1e-3:
        return
    d = CLFDriver()
    base = d.solve([x, y, th, v], [gx, gy])
    turned = d.solve([x, y, th + 2 * math.pi * k, v], [gx, gy])
    np.testing.assert_allclose(turned, base, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(th=st.floats(-3.1, 3.1, **finite), bearing=st.floats(-3.1, 3.1, **finite), v=st.floats(0.0, 2.0, **finite))
def test_the_turn_is_toward_the_goal(th, bearing, v):
    """With the goal 5 m away at ``bearing``, off the heading by ``e = bearing - th`` with
    ``0 < |e| < pi`` (no branch cut between them, so the heuristic keeps the bearing), the turn
    rate has the sign of ``e``: ``u1 = p a b / (1 + p a^2)`` with ``a = -2 e`` and ``b =
    -(0.4 v e sin e + e^2) < 0``, clipped to the box."""
    e = bearing - th
    if not 0.01 < abs(e) < math.pi - 0.01:
        return
    u = CLFDriver().control([0.0, 0.0, th, v], [5 * math.cos(bearing), 5 * math.sin(bearing)])
    a, b = -2 * e, -(0.4 * v * e * math.sin(e) + e * e)
    assert u[0] == pytest.approx(min(max(a * b / (1 + a * a), -0.25), 0.25), rel=1e-9, abs=1e-12)
    assert math.copysign(1.0, u[0]) == math.copysign(1.0, e)


def test_speed_barrier_hand_values():
    """Hand-computed ``u2`` at the speed bounds (goal straight ahead on the heading, so the heading
    row is slack and ``u1 = 0``).  Speed CLF: ``v_d = (d/10)^2``; its unconstrained optimum is
    ``u* = p a b / (1 + p a^2)`` with ``a = 2 (v - v_d)``, ``b = -lambda_v (v - v_d)^2``."""
    d = CLFDriver(u2_bounds=(-0.5, 0.5), v_bounds=(0.0, 2.0))
    # d = 20: v_d = 4 > v_max; at v = 1.9 the CLF wants +0.5 (the box) but the max-speed barrier
    # allows gamma_vmax (2 - 1.9) = 0.1
    u = d.solve([0.0, 0.0, 0.0, 1.9], [20.0, 0.0])
    assert u[0] == 0.0 and u[1] == pytest.approx(0.1, abs=1e-12)
    u = CLFDriver(params=DriverParams(gamma_vmax=3.0)).solve([0.0, 0.0, 0.0, 1.9], [20.0, 0.0])
    assert u[1] == pytest.approx(0.3, abs=1e-12)
    # over v_max (v = 2.2, goal far): the barrier forces braking of at least 0.2
    assert d.solve([0.0, 0.0, 0.0, 2.2], [20.0, 0.0])[1] == pytest.approx(-0.2, abs=1e-12)
    # d = 1: v_d = 0.01; at v = 0.3: a = 0.58, b = -0.0841: u* = -0.0487780 / 1.3364 = -0.03650;
    # the min-speed barrier allows -gamma_vmin v: -0.3 at gain 1 (u* stands), -0.03 at gain 0.1
    u = d.solve([0.0, 0.0, 0.0, 0.3], [1.0, 0.0])
    assert u[1] == pytest.approx(0.58 * -0.0841 / (1 + 0.58**2), rel=1e-12)
    u = CLFDriver(params=DriverParams(gamma_vmin=0.1)).solve([0.0, 0.0, 0.0, 0.3], [1.0, 0.0])
    assert u[1] == pytest.approx(-0.03, abs=1e-12)
    # the two barriers cannot hold together (v = 3 > v_max + 0.5): the documented point clip(0)
    assert d.solve([0.0, 0.0, 0.0, 3.0], [20.0, 0.0])[1] == 0.0
    z = CLFDriver(u2_bounds=(0.1, 0.5)).solve([0.0, 0.0, 0.0, 3.0], [20.0, 0.0])
    assert z[1] == 0.1


# ------------------------------------------------------------------ the maze's pursuit driver
def _pursuit(lookahead=50.0, gain=1.0, u_max=0.2):
    d = PursuitDriver(u_max=u_max, lookahead=lookahead, gain=gain)
    d.reset([(0.0, 0.0), (100.0, 0.0), (100.0, 100.0)])
    return d


def test_pursuit_target_hand_values():
    """An L-shaped path (100 px east, then 100 px north), look-ahead 50 px: the target is the point
    50 px further along the path than the car's projection on it."""
    d = _pursuit()
    assert d.target(10.0, 3.0) == pytest.approx((60.0, 0.0))
    assert d.target(90.0, -2.0) == pytest.approx((100.0, 40.0))  # round the corner
    assert d.target(104.0, 30.0) == pytest.approx((100.0, 80.0))  # on the second segment now
    assert d.target(10.0, 0.0) == pytest.approx((100.0, 50.0))  # progress never runs back a segment
    assert d.target(100.0, 70.0) == (100.0, 100.0)  # past the end: the goal itself


@settings(max_examples=100, deadline=None)
@given(
    psi=st.floats(-math.pi, math.pi, **finite),
    bearing=st.floats(-math.pi, math.pi, **finite),
    k=st.integers(-2, 2),
    gain=st.floats(0.1, 5.0, **finite),
)
def test_pursuit_turns_by_the_wrapped_bearing_error(psi, bearing, k, gain):
    """``u = clip(gain * wrap(bearing - psi), -u_max, u_max)`` with the error wrapped to
    ``[-pi, pi)``: the car turns the short way, and a heading plus full turns is the same heading."""
    d = PursuitDriver(u_max=0.2, lookahead=1e6, gain=gain)  # the target is the path's end
    d.reset([(0.0, 0.0), (1000.0 * math.cos(bearing), 1000.0 * math.sin(bearing))])
    err = (bearing - psi + math.pi) % (2 * math.pi) - math.pi
    if abs(abs(err) - math.pi) < 1e-6:  # exactly behind: either turn
        return
    u = d.control([0.0, 0.0, psi + 2 * math.pi * k])
    assert u == pytest.approx(min(max(gain * err, -0.2), 0.2), abs=1e-6)
    assert -0.2 <= u <= 0.2


def test_pursuit_wraps_the_error_across_the_branch_cut():
    """Heading 3.0 rad with the target at bearing -3.0 rad: the target is 0.283 rad to the left
    (2 pi - 6), not 6 rad to the right."""
    d = PursuitDriver(u_max=0.2, lookahead=1e6, gain=0.5)
    d.reset([(0.0, 0.0), (1000.0 * math.cos(-3.0), 1000.0 * math.sin(-3.0))])
    assert d.control([0.0, 0.0, 3.0]) == pytest.approx(0.5 * (2 * math.pi - 6.0), rel=1e-9)
    assert d.control([0.0, 0.0, -3.0 + 0.1]) == pytest.approx(-0.05, rel=1e-9)


# ------------------------------------------------------------------ arguments
GAINS = ("gamma_vmin", "gamma_vmax", "lambda_theta", "lambda_v", "p_theta", "p_v")


@pytest.mark.parametrize("name", GAINS)
@pytest.mark.parametrize("bad", [-1.0, math.nan, math.inf, -math.inf, "1", None])
def test_driver_parameters_are_checked_by_name(name, bad):
    op = "> 0" if name.startswith("p_") else ">= 0"
    with pytest.raises(ValueError, match=rf"^driver parameter {name} must be a finite number {op}, got {bad!r}$"):
        DriverParams(**{name: bad})


def test_driver_parameter_bounds_and_layout():
    """Gains may be 0 (a row turned off by choice), slack weights may not (the QP must stay
    strictly convex); ``as_array`` is the order the compiled solver reads."""
    for name in GAINS[:4]:
        assert getattr(DriverParams(**{name: 0}), name) == 0
    for name in GAINS[4:]:
        with pytest.raises(ValueError, match=rf"{name} must be a finite number > 0, got 0"):
            DriverParams(**{name: 0})
    assert DriverParams(1, 2, 3, 4, 5, 6).as_array().tolist() == [1, 2, 3, 4, 5, 6]
    d = CLFDriver(u1_bounds=(-1, 2), u2_bounds=(-3, 4), v_bounds=(0.5, 6))
    assert d.lim.tolist() == [-1, 2, -3, 4, 0.5, 6] and d.gain.tolist() == [1] * 6
    for kw in ({"u1_bounds": (1, -1)}, {"u2_bounds": (0.1, 0.0)}):
        with pytest.raises(ValueError, match=r"control bounds must satisfy min <= max, got"):
            CLFDriver(**kw)
    CLFDriver(u1_bounds=(0.2, 0.2))  # an interval of one point is an interval
    with pytest.raises(ValueError, match=r"^driver solver must be one of \('closed_form', 'osqp'\), got 'cvxpy'$"):
        CLFDriver(solver="cvxpy")


@pytest.mark.parametrize(
    "states, goals",
    [
        (np.zeros((3, 3)), np.zeros((3, 2))),
        (np.zeros(4), np.zeros(2)),
        (np.zeros((3, 4)), np.zeros((3, 1))),
        (np.zeros((3, 4)), np.zeros((2, 2))),
    ],
)
def test_clf_qp_refuses_bad_shapes(states, goals):
    with pytest.raises(
        ValueError, match=rf"states must be \(N, 4\) and goals \(N, 2\), got {re.escape(str(states.shape))}"
    ):
        clf_qp(states, goals, CLFDriver().lim, CLFDriver().gain)


def test_wider_rows_and_an_output_array_are_accepted():
    """States of the env (more than 4 columns) and goal circles (x, y, r) are read by their first
    columns; ``out`` is written in place and returned."""
    d = CLFDriver()
    s, g = np.array([[1.0, 2.0, 0.3, 1.0, 99.0]]), np.array([[5.0, -1.0, 0.7]])
    out = np.full((1, 4), np.nan)
    r = clf_qp(s, g, d.lim, d.gain, out=out)
    assert r is out and np.array_equal(out, clf_qp(s[:, :4], g[:, :2], d.lim, d.gain))
    assert np.array_equal(d.control(s[0], g[0]), out[0, :2]) and np.array_equal(d.solve(s[0], g[0]), out[0])


@pytest.mark.parametrize(
    "kw, name",
    [
        ({"u_max": 0.0}, "u_max"),
        ({"lookahead": -1.0}, "lookahead"),
        ({"gain": math.nan}, "gain"),
        ({"u_max": True}, "u_max"),
        ({"lookahead": "190"}, "lookahead"),
        ({"gain": math.inf}, "gain"),
    ],
)
def test_pursuit_arguments_are_checked_by_name(kw, name):
    args = {"u_max": 0.2} | kw
    with pytest.raises(ValueError, match=rf"^{name} must be a finite number > 0, got {kw[name]!r}$"):
        PursuitDriver(**args)


def test_pursuit_waypoints_are_checked():
    d = PursuitDriver(u_max=0.2)
    assert d.waypoints.shape == (0, 2)
    for bad in (
        [(0.0, 0.0)],
        [(0.0, 0.0, 0.0), (1.0, 1.0, 1.0)],
        [(0.0, 0.0), (math.inf, 1.0)],
        [[[0.0, 0.0], [1.0, 1.0]]],
    ):
        with pytest.raises(ValueError, match=r"^waypoints must be \(K >= 2, 2\) finite points, got shape"):
            d.reset(bad)


def test_pursuit_defaults_and_projection_past_a_corner():
    d = PursuitDriver(u_max=0.2)
    assert (d.u_max, d.lookahead, d.gain) == (0.2, 190.0, 1.0)  # the env's look-ahead, one rad/s per rad
    d = _pursuit()
    # past the corner's x and below the first segment: the projection stops at the corner (t = 1),
    # equally near both segments, so the first is kept: 50 px on from the corner
    assert d.target(110.0, -5.0) == pytest.approx((100.0, 50.0))


@settings(max_examples=60, deadline=None)
@given(
    dx=st.floats(-500.0, 500.0, **finite),
    dy=st.floats(-500.0, 500.0, **finite),
    x=st.floats(-20.0, 120.0, **finite),
    y=st.floats(-20.0, 120.0, **finite),
)
def test_pursuit_target_moves_with_the_path(dx, dy, x, y):
    """Translating the path and the car translates the target (segment lengths and projections
    depend on differences only)."""
    a, b = _pursuit(), PursuitDriver(u_max=0.2, lookahead=50.0)
    b.reset([(dx, dy), (100.0 + dx, dy), (100.0 + dx, 100.0 + dy)])
    tx, ty = a.target(x, y)
    ux, uy = b.target(x + dx, y + dy)
    assert ux == pytest.approx(tx + dx, abs=1e-6) and uy == pytest.approx(ty + dy, abs=1e-6)


def test_cell_path_reads_passages_as_indices_and_names_an_unreachable_cell():
    from types import SimpleNamespace

    from rmm_envs.systems.maze.driver import cell_path

    maze = SimpleNamespace(
        cells=np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0]]), passages=[[0.0, 1.0], [2.0, 1.0]]
    )  # numbers that are not ints, as JSON may give them
    assert cell_path(maze, 0, 2) == [0, 1, 2] and cell_path(maze, 2, 0) == [2, 1, 0] and cell_path(maze, 1, 1) == [1]
    with pytest.raises(ValueError) as e:
        cell_path(maze, 0, 3)
    assert str(e.value) == "cell 3 cannot be reached from cell 0 through the maze's passages"
    with pytest.raises(ValueError, match=r"^goal cell must be in \[0, 4\), got 4$"):
        cell_path(maze, 0, 4)
    with pytest.raises(ValueError, match=r"^start cell must be in \[0, 4\), got -1$"):
        cell_path(maze, -1, 2)


def test_osqp_checking_solver_batches_and_prints_nothing(capfd):
    """The OSQP driver (for checking) solves a batch row by row (any count, none included) and
    is silent."""
    d = CLFDriver(solver="osqp")
    s = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 2.0, -1.0, 0.5], [3.0, -2.0, 2.5, 1.5]])
    g = np.array([[5.0, 0.0], [-3.0, 4.0], [0.0, 0.0]])
    z = d.solve_batch(s, g)
    assert z.shape == (3, 4) and d.solve_batch(s[:0], g[:0]).shape == (0, 4)
    np.testing.assert_allclose(z, CLFDriver().solve_batch(s, g), atol=1e-5)
    np.testing.assert_allclose(d.controls(s, g), CLFDriver().controls(s, g), atol=1e-5)
    out, err = capfd.readouterr()
    assert out == "" and err == ""


def test_osqp_agrees_with_the_closed_form_to_its_tolerance_on_random_states():
    """The checking solver, at its tolerance 1e-7, agrees with the exact closed form to 1e-6 (the
    module docstring's claim) on 300 random states."""
    rng = np.random.default_rng(0)
    s = np.column_stack([rng.uniform(-10, 10, (300, 2)), rng.uniform(-np.pi, np.pi, 300), rng.uniform(0, 2, 300)])
    g = rng.uniform(-10, 10, (300, 2))
    np.testing.assert_allclose(CLFDriver(solver="osqp").solve_batch(s, g), CLFDriver().solve_batch(s, g), atol=1e-6)


def test_branch_cut_heuristic_edges():
    """The literal heuristic's inequalities: strict about the heading, inclusive about the goal's
    bearing (atan2 returns pi exactly for a goal straight behind on the -x axis)."""
    from rmm_envs.systems.dubins4d.driver import desired_heading

    assert desired_heading(-math.pi, 1.0) == 1.0  # theta = -pi is not in (-pi, 0)
    assert desired_heading(-0.5, math.pi) == -1.5 * math.pi  # the bearing pi is in [pi - 0.5, pi]
    assert desired_heading(-0.5, math.pi - 0.5) == -1.5 * math.pi
    assert desired_heading(0.5, -math.pi) == 1.5 * math.pi and desired_heading(0.5, -math.pi + 0.5) == 1.5 * math.pi
    assert desired_heading(0.0, math.pi) == math.pi and desired_heading(math.pi, -3.0) == -3.0


def test_pursuit_progress_looks_two_segments_ahead_at_most():
    """Short segments (10 px) along the x axis, look-ahead 10 px: from progress on the first segment,
    a car at x = 35 (on the fourth segment) is projected on the third at most (its end, x = 30),
    so it aims at x = 40, not 45."""
    d = PursuitDriver(u_max=0.2, lookahead=10.0)
    d.reset([(10.0 * i, 0.0) for i in range(8)])
    assert d.target(35.0, 0.0) == pytest.approx((40.0, 0.0))
    assert d.target(35.0, 0.0) == pytest.approx((45.0, 0.0))  # the next call continues from there
