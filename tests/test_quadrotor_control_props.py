"""What the quadrotor's cascaded controller and its reckless pilot promise
(``rmm_envs/systems/quadrotor/control.py``, ``rmm_envs/systems/quadrotor/driver.py``).

The controller: each feedback term reads its own state component with the documented sign
(a hand-computed response to every single-component error at hover), and the closed loop
drives hover errors and a yaw-rate error to zero.  The pilot: a waypoint is passed by 3-D
distance, and the command points at the waypoint in the heading frame."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.quadrotor.body import QUADROTOR
from rmm_envs.systems.quadrotor.closed_loop import ClosedLoopQuadrotor
from rmm_envs.systems.quadrotor.control import CommandController, heading_of
from rmm_envs.systems.quadrotor.driver import WaypointPilot
from rmm_envs.systems.quadrotor.rotations import quat_from_euler, quat_to_rot

CTRL = CommandController()
M, G = QUADROTOR.mass, QUADROTOR.gravity
IX, IY, IZ = QUADROTOR.inertia
finite = dict(allow_nan=False, allow_infinity=False)


def hover(roll=0.0, pitch=0.0, yaw=0.0, v=(0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0), z=1.5):
    return np.array([0.0, 0.0, z, *quat_from_euler(roll, pitch, yaw), *v, *w])


# ------------------------------------------------------------------ the wrench, one error at a time
D = 1e-3  # small: the responses below are the exact first-order ones, checked to O(D^2)


@pytest.mark.parametrize("yaw", [0.0, 0.7, -2.5])
def test_each_velocity_error_is_fed_back_through_its_own_axis(yaw):
    """At hover (yaw ``psi``) with a world velocity error ``D`` along one axis and a zero command:

    * along the heading (``(cos psi, sin psi, 0)``): the body pitches back to brake, ``My =
      -I_y k_R sin(atan(k_v D / g))``, no roll, no yaw moment, thrust ``m g`` to first order;
    * to the left of it: the body rolls right (``Mx = +I_x k_R sin(atan(k_v D / g))``);
    * upward: less thrust, ``F = m (g - k_vz D)``, no moment.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    tilt = math.sin(math.atan2(CTRL.k_v * D, G))
    u = CTRL.wrench(hover(yaw=yaw, v=(D * c, D * s, 0.0)), [0, 0, 0, 0])
    np.testing.assert_allclose(u, [M * G, 0.0, -IY * CTRL.k_R * tilt, 0.0], atol=1e-9)
    u = CTRL.wrench(hover(yaw=yaw, v=(-D * s, D * c, 0.0)), [0, 0, 0, 0])
    np.testing.assert_allclose(u, [M * G, IX * CTRL.k_R * tilt, 0.0, 0.0], atol=1e-9)
    u = CTRL.wrench(hover(yaw=yaw, v=(0.0, 0.0, D)), [0, 0, 0, 0])
    np.testing.assert_allclose(u, [M * (G - CTRL.k_vz * D), 0.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("yaw", [0.0, 1.2])
def test_each_rate_and_tilt_error_is_damped_about_its_own_axis(yaw):
    """Body rates are damped about their own axis (``M_i = -I_i k_w w_i``, ``k_wz`` about z), and a
    roll or pitch ``D`` is pulled back (``M = -I k_R sin D`` about that axis; the thrust ``m g cos D``);
    a yaw error is no error (the desired attitude keeps the body's yaw)."""
    R = quat_to_rot(quat_from_euler(0.0, 0.0, yaw))
    for axis, (i, k) in enumerate(((IX, CTRL.k_w), (IY, CTRL.k_w), (IZ, CTRL.k_wz))):
        wb = np.zeros(3)
        wb[axis] = D
        u = CTRL.wrench(hover(yaw=yaw, w=R @ wb), [0, 0, 0, 0])  # world-frame rate of the body-frame D
        expect = np.zeros(3)
        expect[axis] = -i * k * D
        np.testing.assert_allclose(u, [M * G, *expect], atol=1e-12)
    u = CTRL.wrench(hover(roll=D, yaw=yaw), [0, 0, 0, 0])
    np.testing.assert_allclose(u, [M * G * math.cos(D), -IX * CTRL.k_R * math.sin(D), 0.0, 0.0], atol=1e-9)
    u = CTRL.wrench(hover(pitch=D, yaw=yaw), [0, 0, 0, 0])
    np.testing.assert_allclose(u, [M * G * math.cos(D), 0.0, -IY * CTRL.k_R * math.sin(D), 0.0], atol=1e-9)
    np.testing.assert_allclose(CTRL.wrench(hover(yaw=yaw + D), [0, 0, 0, 0]), [M * G, 0, 0, 0], atol=1e-12)


@pytest.mark.parametrize(
    "cmd, expect",
    [
        ([0, 0, 0, 0.5], [M * G, 0, 0, IZ * 10.0 * 0.5]),  # yaw rate left: +Mz (k_wz = 10)
        ([0, 0, 0, -0.5], [M * G, 0, 0, -IZ * 10.0 * 0.5]),
        ([0, 0, -0.5, 0], [M * (G - 3.0 * 0.5), 0, 0, 0]),  # descend: k_vz = 3
        ([0, 0.4, 0, 0], [M * G, -IX * 400.0 * math.sin(math.atan2(2.5 * 0.4, G)), 0, 0]),  # left: roll left
        ([-0.4, 0, 0, 0], [M * G, 0, -IY * 400.0 * math.sin(math.atan2(2.5 * 0.4, G)), 0]),  # back: pitch back
    ],
)
def test_command_sign_conventions(cmd, expect):
    """The documented sign of each command at a level body at rest: ``yaw_rate > 0`` turns left
    (counter-clockwise seen from above), ``v_left > 0`` rolls the body toward +y (a negative
    ``Mx``), ``v_forward < 0`` pitches it back, ``v_up < 0`` lowers the thrust."""
    np.testing.assert_allclose(CTRL.wrench(hover(), cmd), expect, atol=1e-12)


# ------------------------------------------------------------------ the closed loop converges
LOOP = ClosedLoopQuadrotor()


@settings(max_examples=12, deadline=None)
@given(
    tilt=st.tuples(st.floats(-0.4, 0.4, **finite), st.floats(-0.4, 0.4, **finite)),
    yaw=st.floats(-math.pi, math.pi, **finite),
    v=st.tuples(*[st.floats(-1.5, 1.5, **finite)] * 3),
    w=st.tuples(*[st.floats(-2.0, 2.0, **finite)] * 3),
)
def test_a_zero_command_brings_any_small_error_to_hover(tilt, yaw, v, w):
    """From a tilted, moving, spinning body, the zero command (hover and level) stops it and levels
    it within 4 s: every velocity and rate below 1 cm/s (rad/s), the body z axis vertical."""
    s = hover(roll=tilt[0], pitch=tilt[1], yaw=yaw, v=v, w=w, z=5.0)[None]
    end = LOOP.propagate(s, np.zeros((1, 4)), 4.0, 2)[0, -1]
    assert np.abs(end[7:13]).max() < 0.01
    assert quat_to_rot(end[3:7])[2, 2] > 1 - 1e-5


@pytest.mark.parametrize("cmd", [[0.0, 0.0, 0.0, 0.6], [0.0, 0.0, 0.0, -0.8], [1.0, -0.5, 0.3, 0.0]])
def test_the_loop_tracks_a_yaw_rate_and_a_velocity(cmd):
    """Held for 4 s from hover, a command is tracked: the yaw rate to within 0.01 rad/s (angular
    damping leaves ``d (1 + |w|) w / k_wz`` of steady-state error), the heading-frame velocity
    to within the drag's steady-state error (0.1 m/s)."""
    end = LOOP.propagate(hover(z=5.0)[None], np.array([cmd]), 4.0, 2)[0, -1]
    assert end[12] == pytest.approx(cmd[3], abs=0.01)
    psi = heading_of(end[3:7])
    vx, vy, vz = end[7:10]
    fwd, left = math.cos(psi) * vx + math.sin(psi) * vy, -math.sin(psi) * vx + math.cos(psi) * vy
    np.testing.assert_allclose([fwd, left, vz], cmd[:3], atol=0.1)
    assert abs(end[10]) < 0.01 and abs(end[11]) < 0.01


def test_yaw_rate_is_a_rate_about_the_world_vertical():
    """A yaw-rate command of 0.5 rad/s held for 3 s from yaw 0 turns the heading left by about
    1.5 rad (less the ramp-up: the rate loop's time constant is 1 / k_wz = 0.1 s)."""
    path = LOOP.propagate(hover(z=5.0)[None], np.array([[0.0, 0.0, 0.0, 0.5]]), 3.0, 2)[0]
    assert heading_of(path[-1, 3:7]) == pytest.approx(1.5 - 0.5 * 0.1, abs=0.02)


# ------------------------------------------------------------------ the pilot
def pilot(**kw):
    return WaypointPilot(CTRL.command_low, CTRL.command_high, **kw)


point = st.tuples(*[st.floats(-3.0, 3.0, **finite)] * 3)


@settings(max_examples=150, deadline=None)
@given(pos=point, wps=st.lists(point, min_size=1, max_size=5), reach=st.floats(0.2, 2.0, **finite))
def test_pilot_passes_exactly_the_waypoints_within_reach_in_3d(pos, wps, reach):
    """After one command, the pilot flies to the first waypoint (in order) that is at least
    ``reach`` away from the body in 3-D, or to the last one (the goal is never passed)."""
    p = pilot(reach=reach)
    p.reset(wps)
    p.command(np.array([*pos, 0.0, 0.0, 0.0, 1.0, 0, 0, 0, 0, 0, 0]))
    expect = next((i for i, w in enumerate(wps[:-1]) if math.dist(pos, w) >= reach), len(wps) - 1)
    assert p.index == expect
    np.testing.assert_array_equal(p.target, wps[expect])


def test_pilot_does_not_pass_a_waypoint_above_or_below_it():
    """Horizontally on the waypoint but 1 m under it (reach 0.5): not passed; the pilot climbs
    (and does not turn: within reach horizontally).  Within reach in 3-D: passed."""
    p = pilot()
    p.reset([[2.0, 1.0, 2.5], [5.0, 1.0, 2.5]])
    cmd = p.command(hover(z=1.5) + np.r_[2.0, 1.0, np.zeros(11)])
    assert p.index == 0 and cmd.tolist() == [0.0, 0.0, 0.5, 0.0]
    p.command(hover(z=2.2) + np.r_[2.0, 0.7, np.zeros(11)])  # 0.3 low, 0.3 aside: 0.42 m
    assert p.index == 1
    p.reset([[2.0, 1.0, 2.5], [5.0, 1.0, 2.5]])
    p.command(hover(z=2.5) + np.r_[1.55, 0.7, np.zeros(11)])  # 0.45 and 0.3 aside: 0.54 m, not within
    assert p.index == 0


@settings(max_examples=100, deadline=None)
@given(
    pos=point,
    wp=point,
    yaw=st.floats(-math.pi, math.pi, **finite),
    tilt=st.tuples(st.floats(-0.5, 0.5, **finite), st.floats(-0.5, 0.5, **finite)),
)
def test_pilot_command_points_at_the_waypoint_in_the_heading_frame(pos, wp, yaw, tilt):
    """The command's horizontal velocity, turned back into the world by ``psi`` (the yaw of the
    body x axis, whatever the tilt), is ``gain (w - p)_xy`` limited to the cruise speed; the climb
    is ``gain (w - p)_z`` limited to the climb speed; the yaw rate turns toward the waypoint's
    bearing the short way (clipped to the box)."""
    p = pilot()
    p.reset([wp])
    body = hover(roll=tilt[0], pitch=tilt[1], yaw=yaw)
    yaw = float(heading_of(body[3:7]))
    cmd = p.command(body + np.r_[pos[0], pos[1], pos[2] - 1.5, np.zeros(10)])
    dx, dy, dz = wp[0] - pos[0], wp[1] - pos[1], wp[2] - pos[2]
    world = np.array([math.cos(yaw) * cmd[0] - math.sin(yaw) * cmd[1], math.sin(yaw) * cmd[0] + math.cos(yaw) * cmd[1]])
    want = np.array([dx, dy]) * min(1.0, 1.5 / math.hypot(dx, dy)) if math.hypot(dx, dy) > 0 else np.zeros(2)
    np.testing.assert_allclose(world, want, atol=1e-9)  # 1.5 m/s is inside the box: never clipped
    assert cmd[2] == pytest.approx(min(max(dz, -0.5), 0.5), abs=1e-12)
    if math.hypot(dx, dy) <= 0.5:
        assert cmd[3] == 0.0
    else:
        err = (math.atan2(dy, dx) - yaw + math.pi) % (2 * math.pi) - math.pi
        assert cmd[3] == pytest.approx(min(max(2.0 * err, -1.0), 1.0), abs=1e-9)


@pytest.mark.parametrize("name", ["cruise_speed", "climb_speed", "gain", "yaw_gain", "reach"])
@pytest.mark.parametrize("bad", [0, 0.0, -1.0, math.nan, math.inf, True, "1"])
def test_pilot_arguments_are_checked_by_name(name, bad):
    with pytest.raises(ValueError, match=rf"^{name} must be a finite number > 0, got {bad!r}$".replace("(", r"\(")):
        pilot(**{name: bad})
    p = pilot(**{name: 1e-9})  # any positive number is accepted, as given
    assert getattr(p, name) == 1e-9


def test_pilot_reads_its_box_and_waypoints_as_given():
    p = WaypointPilot(np.array([[-1, -2], [-3, -4]]), np.array([[1, 2], [3, 4]]))  # integers, any shape of 4 numbers
    assert p.low.tolist() == [-1, -2, -3, -4] and p.high.tolist() == [1, 2, 3, 4] and p.index == 0
    assert p.low.shape == p.high.shape == (4,) and p.low.dtype == p.high.dtype == np.float64
    assert p.waypoints.shape == (0, 3)
    w = np.array([[1.0, 2.0, 3.0]])
    p.reset(w)
    w[0, 0] = 9.0  # the pilot keeps its own copy
    assert p.target.tolist() == [1.0, 2.0, 3.0]
    p.reset([[1, 2, 3]])
    assert p.target.dtype == np.float64
    for bad in ([[1.0, 2.0]], np.zeros((0, 3)), [[1.0, math.nan, 2.0]], [[[1.0, 2.0, 3.0]]]):
        with pytest.raises(ValueError, match=r"waypoints must be \(K >= 1, 3\) finite points, got shape"):
            p.reset(bad)
    p.reset([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0]])
    p.index = 1
    p.reset([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0]])
    assert p.index == 0  # a reset starts from the first waypoint


def test_pilot_commands_are_clipped_to_the_box_it_is_given():
    """A tight box (0.3 m/s each way, 0.1 rad/s): every number of the command clipped to it."""
    p = WaypointPilot([-0.3, -0.3, -0.3, -0.1], [0.3, 0.3, 0.3, 0.1])
    p.reset([[10.0, 10.0, 10.0]])
    assert p.command(hover()).tolist() == [0.3, 0.3, 0.3, 0.1]
    p.reset([[-10.0, -10.0, -10.0]])
    assert p.command(hover()).tolist() == [-0.3, -0.3, -0.3, -0.1]


def test_pilot_boundaries_at_exactly_reach():
    """A waypoint exactly ``reach`` (0.5 m) away is not within reach: not passed, and (the last
    one, 0.5 m to the left) still turned toward; a turn needs more than ``reach`` horizontally."""
    p = pilot()
    p.reset([[0.0, 0.5, 1.5], [5.0, 0.0, 1.5]])
    p.command(hover())
    assert p.index == 0
    p.reset([[0.0, 0.5, 1.5]])
    assert p.command(hover())[3] == 0.0  # 0.5 m is not more than reach: no turn
    p.reset([[0.0, 0.5 + 1e-9, 1.5]])
    assert p.command(hover())[3] == 1.0  # just beyond it: the turn (2 x pi/2, clipped to 1)


# ------------------------------------------------------------------ the controller's arguments and packed gains
@pytest.mark.parametrize("name", ["k_v", "k_vz", "a_max_h", "a_max_z", "k_R", "k_w", "k_wz"])
@pytest.mark.parametrize("bad", [0, -1.0, math.nan, math.inf, True, "1"])
def test_controller_gains_are_refused_by_exact_message(name, bad):
    with pytest.raises(ValueError) as e:
        CommandController(**{name: bad})
    assert str(e.value) == f"CommandController.{name} must be a finite number > 0, got {bad!r}"


BOUNDS = "CommandController: command bounds must be 4 finite numbers each with low <= 0 <= high (zero is hover), got "


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"a_max_z": 9.81}, "CommandController.a_max_z must be below gravity (9.81), got 9.81"),
        ({"command_low": (-1, -1, -1)}, BOUNDS + "(-1, -1, -1) and (2.0, 2.0, 1.0, 1.0)"),
        ({"command_high": (1, 1, 1, math.inf)}, BOUNDS + "(-2.0, -2.0, -1.0, -1.0) and (1, 1, 1, inf)"),
        ({"command_low": (0.5, -1, -1, -1)}, BOUNDS + "(0.5, -1, -1, -1) and (2.0, 2.0, 1.0, 1.0)"),
        ({"command_high": (1, 1, -0.1, 1)}, BOUNDS + "(-2.0, -2.0, -1.0, -1.0) and (1, 1, -0.1, 1)"),
        ({"command_low": (-1, -1, -1, math.nan)}, BOUNDS + "(-1, -1, -1, nan) and (2.0, 2.0, 1.0, 1.0)"),
    ],
)
def test_controller_bounds_are_refused_by_exact_message(kw, message):
    with pytest.raises(ValueError) as e:
        CommandController(**kw)
    assert str(e.value) == message


def test_controller_keeps_its_arguments_and_packs_the_gains_in_the_kernels_order():
    c = CommandController(
        command_low=np.array([[-1, -2], [-3, 0]]), command_high=np.array([[0, 2], [3, 4]]), k_v=1.5, a_max_z=9.8
    )
    assert c.command_low == (-1.0, -2.0, -3.0, 0.0) and c.command_high == (0.0, 2.0, 3.0, 4.0)
    assert all(type(x) is float for x in c.command_low + c.command_high)
    assert CommandController().packed.tolist() == [
        0.5,
        9.81,
        0.0023,
        0.0023,
        0.004,
        2.5,
        3.0,
        5.0,
        4.0,
        400.0,
        36.0,
        10.0,
        0.0,
        8.0,
        -2.0,
        -2.0,
        -1.0,
        2.0,
        2.0,
        1.0,
    ]
    assert c.packed[5] == 1.5 and c.packed[8] == 9.8 and not c.packed.flags.writeable
    with pytest.raises(TypeError) as e:
        CommandController(params="heavy")
    assert str(e.value) == "CommandController(params=...) needs a QuadrotorParams, got str"


def test_a_command_outside_the_box_is_clipped_to_it_and_hover_and_level_is_zero():
    from rmm_envs.autonomy import GuardianActionSpace
    from rmm_envs.systems.quadrotor.control import HoverAndLevel

    np.testing.assert_array_equal(
        CTRL.wrench(hover(), [9.0, -9.0, 9.0, -9.0]), CTRL.wrench(hover(), [2.0, -2.0, 1.0, -1.0])
    )
    space = GuardianActionSpace(("a", "b", "c", "d"), [-2.0, 0.5, -1.0, -1.0], [2.0, 2.0, -0.5, 1.0])
    act = HoverAndLevel().policy(space, np.random.default_rng(0))
    assert act(None).tolist() == [0.0, 0.5, -0.5, 0.0]  # zero, within the box
    assert HoverAndLevel.description == "hover and level (the zero command)"
    with pytest.raises(ValueError):
        HoverAndLevel().policy(space, np.random.default_rng(0), speed=1.0)


def test_closed_loop_system_box_and_samples():
    rng = np.random.default_rng(5)
    u = LOOP.sample_controls(rng, 500)
    assert u.shape == (500, 4) and np.all(u >= LOOP.control_low) and np.all(u <= LOOP.control_high)
    assert np.all(u.min(axis=0) < LOOP.control_low + 0.1) and np.all(u.max(axis=0) > LOOP.control_high - 0.1)
    assert LOOP.control_low.tolist() == [-2.0, -2.0, -1.0, -1.0] and LOOP.control_high.tolist() == [2.0, 2.0, 1.0, 1.0]
    assert (LOOP.state_dim, LOOP.control_dim) == (13, 4) and LOOP.body.params is QUADROTOR


@settings(max_examples=40, deadline=None)
@given(q=st.tuples(*[st.floats(-1.0, 1.0, **finite)] * 4))
def test_scalar_and_array_yaw_agree_and_read_the_body_x_axis(q):
    from rmm_envs.systems.quadrotor.control import yaw_of

    n = math.sqrt(sum(x * x for x in q))
    if n < 0.1:
        return
    q = np.array(q) / n
    R = quat_to_rot(q)
    if math.hypot(R[0, 0], R[1, 0]) < 1e-3:
        return
    assert yaw_of(*q) == pytest.approx(float(heading_of(q)), abs=1e-12)
    assert yaw_of(*q) == pytest.approx(math.atan2(R[1, 0], R[0, 0]), abs=1e-9)
    np.testing.assert_allclose(heading_of(np.array([q, q])), [yaw_of(*q)] * 2, atol=1e-12)


def test_hover_and_level_is_held_exactly_by_the_closed_loop():
    """At rest, level, the zero command: thrust m g, no moment, no rotation step: every point of
    the path is the start (to the last bit of the quaternion's renormalisation)."""
    s = hover(yaw=0.4, z=3.0)
    path = LOOP.propagate(s[None], np.zeros((1, 4)), 2.0, 5)[0]
    np.testing.assert_allclose(path, np.repeat(s[None], 5, axis=0), rtol=0, atol=1e-12)


def test_the_gyroscopic_term_and_the_moment_bounds_by_hand():
    """Level hover, body rates ``w_b`` on two axes: ``M = I (-k_w w_b) + w_b x I w_b`` (``k_wz`` about
    z), e.g. ``Mx = w_y w_z (I_z - I_y)``; a pitch-rate error of 20 rad/s asks 1.656 N m, inside the
    2 N m pitch bound (the yaw bound is 1)."""
    for wb in ((0.0, 0.5, 2.0), (0.7, 0.0, -1.5), (1.0, -2.0, 0.0)):
        wx, wy, wz = wb
        u = CTRL.wrench(hover(w=wb), [0, 0, 0, 0])
        expect = [
            IX * -36.0 * wx + wy * wz * (IZ - IY),
            IY * -36.0 * wy + wz * wx * (IX - IZ),
            IZ * -10.0 * wz + wx * wy * (IY - IX),
        ]
        np.testing.assert_allclose(u, [M * G, *expect], atol=1e-12)
    np.testing.assert_allclose(
        CTRL.wrench(hover(w=(0.0, -20.0, 0.0)), [0, 0, 0, 0]), [M * G, 0.0, IY * 36.0 * 20.0, 0.0], atol=1e-12
    )
    np.testing.assert_allclose(
        CTRL.wrench(hover(w=(30.0, 0.0, 0.0)), [0, 0, 0, 0]), [M * G, -2.0, 0.0, 0.0], atol=1e-12
    )
    np.testing.assert_allclose(
        CTRL.wrench(hover(w=(0.0, 0.0, -30.0)), [0, 0, 0, 0]), [M * G, 0.0, 0.0, 1.0], atol=1e-12
    )


def test_with_the_body_x_axis_vertical_the_heading_is_zero():
    """Pitched by 90 degrees (any yaw before it), the body x axis is vertical: the heading frame is the
    world's (psi = 0), so "forward" 1 m/s asks a = (2.5, 0, 0) and the thrust is ``m a . z_b`` with
    the horizontal body z axis ``(cos yaw, sin yaw, 0)``."""
    for yaw in (0.0, 1.0, -2.0):
        s = hover(pitch=math.pi / 2, yaw=yaw)
        R = quat_to_rot(s[3:7])
        assert math.hypot(R[0, 0], R[1, 0]) < 1e-12
        F = CTRL.wrench(s, [1.0, 0, 0, 0])[0]
        assert F == pytest.approx(min(max(M * (2.5 * R[0, 2] + G * R[2, 2]), 0.0), 8.0), abs=1e-9)
