"""The CBF guardians' rows, recovery manoeuvre and end of recovery, pinned on hand-computed cases.

Values, not implementation: each case states the geometry and the answer worked out by hand
from the rules of :mod:`rmm_guardians.cbf` (barrier rows, CLF rows, the recovery tangent)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.dubins4d.env import CONTROLS
from rmm_guardians.cbf import CBFGuardian, CBFPaperGuardian
from rmm_guardians.cbf.barrier import HOCBFParams, barrier_rows
from rmm_guardians.cbf.recovery import recovery_control, recovery_done
from tests.test_cbf import INFO0

SPACE = GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, dynamics_name="dubins4d")
# the default gains; the Dubins4D control box and speed range
PRM = HOCBFParams(0.7535, 0.6664, 1.0, 1.0, 1.0, 1.0, -0.25, 0.25, -0.5, 0.5, 0.0, 2.0)
OBST = np.array([[0.0, 0.0, 3.0]])
RADII = np.array([3.15])  # inflation 1.05
FAR_GOAL = np.array([-20.0, 0.0, 0.5])


def rec(state, obstacles=OBST, radii=RADII, goal=FAR_GOAL, lap=0.1):
    return recovery_control(np.asarray(state, float), 0, obstacles, radii, goal, PRM, lap, 0.05)


def test_speed_clf_row_by_hand():
    # goal 1 m ahead: desired speed min((d/2)^2, d/2) = 0.25; at v = 1: e_v = 0.75, row 2 e_v u2 - d_v <= -e_v^2
    for d, v_d in ((1.0, 0.25), (4.0, 2.0)):
        G, h = barrier_rows(
            [0.0, 0.0, 0.0, 1.0], np.array([[9.0, 9.0, 1.0]]), np.array([1.0]), np.array([d, 0.0, 0.5]), PRM
        )
        K = 1
        assert G[K + 5, 1] == pytest.approx(2 * (1.0 - v_d)) and G[K + 5, 3] == -1.0
        assert h[K + 5] == pytest.approx(-((1.0 - v_d) ** 2))


@settings(max_examples=30, deadline=None)
@given(
    th=st.floats(-math.pi + 1e-6, math.pi - 1e-6),
    turns=st.sampled_from([-2, -1, 1, 2]),
    x=st.floats(-5, 5),
    y=st.floats(-5, 5),
    v=st.floats(0, 2),
)
def test_rows_are_periodic_in_the_heading(th, turns, x, y, v):
    obstacles = np.array([[6.0, 1.0, 1.0], [-4.0, -6.0, 2.0]])
    radii, goal = obstacles[:, 2] * 1.05, np.array([9.0, -3.0, 0.5])
    G, h = barrier_rows([x, y, th, v], obstacles, radii, goal, PRM)
    G2, h2 = barrier_rows([x, y, th + 2 * math.pi * turns, v], obstacles, radii, goal, PRM)
    np.testing.assert_allclose(G2, G, atol=1e-9)
    np.testing.assert_allclose(h2, h, atol=1e-9)


@pytest.mark.parametrize("cls", [CBFGuardian, CBFPaperGuardian])
def test_low_speed_stop_brakes_without_turning(cls):
    g = cls(low_speed_stop=True, predict_latency=False)
    box = {
        "state": np.array([0.0, 0.0, 0.3, 0.01]),
        "obstacles": np.array([[30.0, 30.0, 1.0]]),
        "goal": np.array([20.0, 0.0, 0.5]),
        "sim_time": 0.0,
    }
    g.reset(seed=0, privileged=lambda: box, action_space=SPACE)
    a = g.act(None, INFO0)
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == 0.0 and a["accel_ctrl"][0] == -0.5


def test_recovery_outside_the_margin_follows_the_tangent():
    # at (0, 3.2) above the centre, heading +x at 1 m/s: the clockwise tangent is +x (the way the
    # car already goes), so no turn; outside the margin (3.2 > 3.15) no outward component is
    # added; accelerate at min(u2_max, gamma (v_max - v)) = 0.5, which this obstacle's row allows
    u, side = rec([0.0, 3.2, 0.0, 1.0])
    assert side == -1.0 and u[0] == pytest.approx(0.0, abs=1e-12) and u[1] == pytest.approx(0.5)


def test_recovery_inside_the_margin_turns_out_as_it_goes_round():
    # at (0, 3.1), inside the margin: the target is the tangent plus the outward normal, 45
    # degrees left of the heading: turn left at the limit
    u, side = rec([0.0, 3.1, 0.0, 1.0])
    assert side == -1.0 and u[0] == pytest.approx(0.25) and u[1] == pytest.approx(0.5)


def test_recovery_at_the_centre_takes_the_heading_as_the_outward_direction():
    at, _ = rec([0.0, 0.0, 0.7, 0.0])
    near, _ = rec([1e-9 * math.cos(0.7), 1e-9 * math.sin(0.7), 0.7, 0.0])
    np.testing.assert_allclose(at, near, atol=1e-9)


def test_recovery_accelerates_only_as_far_as_an_obstacle_ahead_allows():
    # recovering from obstacle 0 at (3.2, 0), facing out (+x) at 1 m/s, with obstacle 1 (r = 1,
    # margin 1.05) 2.8 m ahead: its row 5.6 u2 <= h_1 caps the acceleration below 0.5:
    # h_1 = 2 v^2 + p1 Lf b + p2 (Lf b + p1 b), Lf b = -5.6, b = 2.8^2 - 1.05^2
    obstacles = np.array([[0.0, 0.0, 3.0], [6.0, 0.0, 1.0]])
    radii = obstacles[:, 2] * 1.05
    b, lfb = 2.8**2 - 1.05**2, -5.6
    h1 = 2.0 + 0.7535 * lfb + 0.6664 * (lfb + 0.7535 * b)
    u, side = rec([3.2, 0.0, 0.0, 1.0], obstacles, radii)
    assert u[0] == pytest.approx(0.25)  # a quarter turn left to the tangent: at the limit
    assert u[1] == pytest.approx(h1 / 5.6) and -0.5 < u[1] < 0.0


def test_recovery_ends_only_when_the_straight_line_to_the_goal_clears_the_margin():
    # outside the margin, heading away (north) from (-6, 3.2): the segment to (6, 3.0) passes
    # about 3.10 m from the centre, inside the 3.15 m margin; the one to (6, 3.4), about 3.30 m
    s = np.array([-6.0, 3.2, math.pi / 2, 1.0])
    b = np.array([s[0] ** 2 + s[1] ** 2 - 3.15**2])
    assert not recovery_done(s, b, 0, OBST, RADII, np.array([6.0, 3.0, 0.5]))
    assert recovery_done(s, b, 0, OBST, RADII, np.array([6.0, 3.4, 0.5]))
    # heading back toward the centre: not over
    assert not recovery_done(np.array([-6.0, 3.2, -math.pi / 2, 1.0]), b, 0, OBST, RADII, np.array([6.0, 3.4, 0.5]))
    # a goal overlapping the margin: no detour clears it, the recovery ends (the QP takes over)
    assert recovery_done(s, b, 0, OBST, RADII, np.array([0.0, 3.0, 0.5]))
    # standing on the goal's centre, outside the margin and heading away: over
    on_goal = np.array([-6.0, 3.2, 0.5])
    assert recovery_done(s, b, 0, OBST, RADII, on_goal)
    # inside some margin: never over
    assert not recovery_done(s, np.array([-0.1]), 0, OBST, RADII, np.array([6.0, 3.4, 0.5]))
