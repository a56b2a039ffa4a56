import math

import numpy as np
import pytest

from rmm_envs.driver import CLFDriver, desired_heading
from tests.qp_reference import solve_qp_dense


def test_acceptance_value():
    d = CLFDriver(u1_bounds=(-0.1, 0.1), u2_bounds=(-0.5, 0.5))
    np.testing.assert_allclose(d.solve(np.zeros(4), (5.0, 0.0)), [0.0, 0.025, 0.0, 0.05], atol=1e-4)


def _reference(state, goal, u1b=(-0.25, 0.25), u2b=(-0.5, 0.5)):
    """An exact dense solve of the same QP, built from the REFERENCE rows (unmerged)."""
    x, y, th, v = state
    xh, yh = goal[0] - x, goal[1] - y
    d2 = xh * xh + yh * yh
    vd = (math.sqrt(d2) / 10) ** 2
    th = (th + math.pi) % (2 * math.pi) - math.pi
    thd = desired_heading(th, math.atan2(yh, xh))
    e = th - thd
    lf = 2 * v * e * (xh * math.sin(th) - yh * math.cos(th)) / d2
    G = np.array([
        [0, 1, 0, 0], [0, -1, 0, 0], [1, 0, 0, 0], [-1, 0, 0, 0], [0, 1, 0, 0], [0, -1, 0, 0],
        [2 * e, 0, -1, 0], [0, 2 * (v - vd), 0, -1],
    ], float)
    h = np.array([2 - v, v, u1b[1], -u1b[0], u2b[1], -u2b[0], -lf - e * e, -(v - vd) ** 2])
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
