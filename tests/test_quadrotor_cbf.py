"""The quadrotor ``cbf`` (rmm_guardians.cbf.quadrotor): hand-computed barrier rows, the filter's
properties, the recovery, bad input, dispatch and a fixed-clock episode."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.quadrotor.closed_loop import ClosedLoopQuadrotor
from rmm_envs.systems.quadrotor.control import CommandController
from rmm_envs.systems.quadrotor.guarded import CONTROLS, QuadrotorRoomGuardedEnv
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rooms import Room
from rmm_envs.systems.quadrotor.rotations import quat_from_euler
from rmm_guardians import make_guardian
from rmm_guardians.cbf.quadrotor import QuadrotorCBFGuardian
from rmm_guardians.cbf.quadrotor_rows import BOX, CYLINDER, FLOOR, SPHERE, command_rows, room_shapes, shape_distances

TAU_H, TAU_Z, P1, P2 = 0.42, 0.34, 2.0, 2.0
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def level(x=0.0, y=0.0, z=1.5, yaw=0.0, v=(0.0, 0.0, 0.0)):
    return np.array([x, y, z, *quat_from_euler(0.0, 0.0, yaw), *v, 0.0, 0.0, 0.0])


def room(walls=(), objects=()):
    """A 20 m x 20 m footprint (origin -10, -10) with the given walls and objects."""
    return Room(
        footprint=np.ones((40, 40), bool),
        origin=np.array([-10.0, -10.0]),
        cell=0.5,
        wall_height=3.0,
        walls=np.array(walls, float).reshape(-1, 6),
        objects=list(objects),
    )


def obj(shape, pos, size, quat=IDENTITY):
    return {"shape": shape, "pos": np.array(pos, float), "quat": np.asarray(quat, float), "size": np.array(size, float)}


def one_row(r, state, shape_index, rho=0.5):
    """The row of shape ``shape_index`` of ``r`` at ``state``: ``(b, G, h)``."""
    shapes = room_shapes(r)
    b, G, h, idx = command_rows(state, shapes, len(shapes), rho, TAU_H, TAU_Z, P1, P2)
    j = int(np.flatnonzero(idx == shape_index)[0])
    return b[j], G[j], h[j]


# ---------------------------------------------------------------- hand-computed rows
def test_row_in_front_of_a_wall():
    """A wall whose face is at x = 1.75, the body at the origin flying at it at 1 m/s, yawed 90
    degrees (forward = world +y, left = world -x): d = 1.75, n = (-1, 0, 0), b = 1.75 - rho;
    b' = -1; the row limits the commanded speed toward the wall, -u_left (world +x)."""
    r = room(walls=[[2.0, 0.0, 1.0, 0.25, 3.0, 1.0]])
    b, G, h = one_row(r, level(z=1.0, yaw=math.pi / 2, v=(1.0, 0.0, 0.0)), 1)
    assert b == pytest.approx(1.75 - 0.5)
    np.testing.assert_allclose(G, [0.0, -1.0 / TAU_H, 0.0], atol=1e-12)
    # h = (p1 + p2) n.v - n_h.v_h / tau_h + p1 p2 b = -4 + 1 / 0.42 + 4 * 1.25
    assert h == pytest.approx(-4.0 + 1.0 / TAU_H + 4.0 * 1.25, abs=1e-12)


def test_row_of_a_sphere_and_of_the_floor():
    """A sphere of radius 0.5 at (0, 3, 1), the body at (0, 0, 1) climbing at 0.5 m/s and flying
    at it at 2 m/s: d = 2.5, n = (0, -1, 0); the floor: d = z = 1, n = e_z."""
    r = room(objects=[obj("sphere", [0.0, 3.0, 1.0], [0.5])])
    s = level(z=1.0, v=(0.0, 2.0, 0.5))
    b, G, h = one_row(r, s, 1)
    assert b == pytest.approx(2.0)
    np.testing.assert_allclose(G, [0.0, 1.0 / TAU_H, 0.0], atol=1e-12)  # yaw 0: forward = x, left = y
    assert h == pytest.approx(4.0 * -2.0 + 2.0 / TAU_H + 4.0 * 2.0, abs=1e-12)
    b, G, h = one_row(r, s, 0)
    assert b == pytest.approx(0.5)
    np.testing.assert_allclose(G, [0.0, 0.0, -1.0 / TAU_Z], atol=1e-12)
    assert h == pytest.approx(4.0 * 0.5 - 0.5 / TAU_Z + 4.0 * 0.5, abs=1e-12)


def test_row_of_a_cylinder_lying_on_its_side():
    """A cylinder of radius 0.5 and length 2, its axis turned onto world x (pitch 90 degrees),
    centred at (0, 0, 0.5): above it the nearest surface is its side (d = 2 - 1 = 1, n = e_z),
    beyond its end the flat cap (d = 3 - 1 = 2, n = e_x)."""
    r = room(objects=[obj("cylinder", [0.0, 0.0, 0.5], [0.5, 2.0], quat_from_euler(0.0, math.pi / 2, 0.0))])
    shapes = room_shapes(r)
    d, n = np.empty(2), np.empty((2, 3))
    shape_distances(np.array([0.3, 0.0, 2.0]), shapes.code, shapes.centre, shapes.rot, shapes.size, d, n)
    assert d[1] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(n[1], [0.0, 0.0, 1.0], atol=1e-12)
    shape_distances(np.array([3.0, 0.0, 0.5]), shapes.code, shapes.centre, shapes.rot, shapes.size, d, n)
    assert d[1] == pytest.approx(2.0, abs=1e-12)
    np.testing.assert_allclose(n[1], [1.0, 0.0, 0.0], atol=1e-12)
    b, G, h = one_row(r, level(x=3.0, z=0.5, v=(-1.0, 0.0, 0.0)), 1)
    assert b == pytest.approx(1.5)
    np.testing.assert_allclose(G, [-1.0 / TAU_H, 0.0, 0.0], atol=1e-12)
    assert h == pytest.approx(-4.0 + 1.0 / TAU_H + 4.0 * 1.5, abs=1e-12)


def test_row_of_a_box_turned_by_45_degrees():
    """A unit cube turned 45 degrees about z at (0, 0, 0.5): from (2, 0, 0.5) its nearest point
    is the vertical edge at x = sqrt(2) / 2, so d = 2 - sqrt(2)/2 and n = e_x; from inside, the
    nearest face."""
    r = room(objects=[obj("box", [0.0, 0.0, 0.5], [0.5, 0.5, 0.5], quat_from_euler(0.0, 0.0, math.pi / 4))])
    shapes = room_shapes(r)
    assert shapes.code.tolist() == [FLOOR, BOX]
    d, n = np.empty(2), np.empty((2, 3))
    shape_distances(np.array([2.0, 0.0, 0.5]), shapes.code, shapes.centre, shapes.rot, shapes.size, d, n)
    assert d[1] == pytest.approx(2.0 - math.sqrt(0.5), abs=1e-12)
    np.testing.assert_allclose(n[1], [1.0, 0.0, 0.0], atol=1e-12)
    shape_distances(np.array([0.0, 0.0, 0.9]), shapes.code, shapes.centre, shapes.rot, shapes.size, d, n)
    assert d[1] == pytest.approx(-0.1, abs=1e-12)  # 0.1 below the top face
    np.testing.assert_allclose(n[1], [0.0, 0.0, 1.0], atol=1e-12)


def test_room_shapes_order_and_codes():
    r = room(
        walls=[[2.0, 0.0, 1.0, 0.25, 3.0, 1.0]],
        objects=[
            obj("sphere", [0, 3, 1], [0.5]),
            obj("cylinder", [3, 3, 0.5], [0.2, 1.0]),
            obj("box", [-3, 0, 0.2], [0.2] * 3),
        ],
    )
    assert room_shapes(r).code.tolist() == [FLOOR, BOX, SPHERE, CYLINDER, BOX]
    with pytest.raises(ValueError, match="room object 0 has shape 'cone'"):
        room_shapes(room(objects=[obj("cone", [0, 0, 0], [1.0])]))


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    st.sampled_from(["box", "cylinder", "sphere"]),
    st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3),
)
def test_the_gradient_is_the_distance_s_derivative(p, shape, angles):
    """Away from an edge, d changes along n at rate 1 and not across it (finite differences)."""
    size = {"box": [0.4, 0.3, 0.6], "cylinder": [0.5, 1.2], "sphere": [0.7]}[shape]
    shapes = room_shapes(room(objects=[obj(shape, [0.0, 0.0, 0.0], size, quat_from_euler(*angles))]))
    d, n = np.empty(2), np.empty((2, 3))
    p = np.array(p)
    shape_distances(p, shapes.code, shapes.centre, shapes.rot, shapes.size, d, n)
    assert abs(np.linalg.norm(n[1]) - 1.0) < 1e-9
    e = 1e-6
    dp, dn = np.empty(2), np.empty((2, 3))
    shape_distances(p + e * n[1], shapes.code, shapes.centre, shapes.rot, shapes.size, dp, dn)
    assert dp[1] - d[1] == pytest.approx(e, rel=1e-3, abs=1e-9) or not np.allclose(dn[1], n[1], atol=1e-6)


# ---------------------------------------------------------------- the guardian on the env
@pytest.fixture(scope="module")
def env():
    e = QuadrotorRoomGuardedEnv()
    yield e
    e.close()


def reset_at(env, g, r, state, goal=(8.0, 8.0, 1.5)):
    obs, info = env.reset(seed=0, options={"room": r, "state": state, "waypoints": [list(goal)]})
    g.reset(
        seed=0,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    return obs, info


def test_cbf_dispatches_to_the_quadrotor_and_cbf_paper_does_not_apply(env):
    g = make_guardian("cbf", env_id="QuadrotorRoomParallel-v0")
    g.check_spaces(env.observation_space, env.action_space)
    reset_at(env, g, room(), level(z=2.0))
    assert isinstance(g.delegate, QuadrotorCBFGuardian) and g.delegate.name == "cbf"
    with pytest.raises(
        ValueError, match=r"guardian 'cbf-paper' applies to Dubins4D envs only: it models the Dubins4D car"
    ):
        make_guardian("cbf-paper").check_spaces(env.observation_space, env.action_space)
    with pytest.raises(ValueError, match="applies to Dubins4D envs and the maze car"):
        make_guardian("cbf", quadrotor=False).check_spaces(env.observation_space, env.action_space)
    with pytest.raises(
        ValueError, match="quadrotor must be a dict of rmm_guardians.cbf.quadrotor.QuadrotorCBFGuardian"
    ):
        make_guardian("cbf", quadrotor="yes")
    with pytest.raises(ValueError, match=r"margin must be a finite number >= 0.0, got -1"):
        make_guardian("cbf", quadrotor={"margin": -1})


def test_away_from_everything_the_pilot_keeps_control(env):
    g = QuadrotorCBFGuardian()
    obs, info = reset_at(env, g, room(), level(z=2.0))
    a = g.act(obs, info)
    assert a["active_ctrl"] == 0 and g.stats()["qp_solves"] == 0


def test_the_filter_lowers_the_speed_toward_a_wall_onto_its_row(env):
    """Flying at a wall 1 m ahead at 1.5 m/s with the pilot asking for 2 m/s: the command is the
    nominal with its component into the wall lowered exactly onto the row at the state predicted
    one lap ahead, the rest (sideways, up) unchanged, the yaw rate zero."""
    g = QuadrotorCBFGuardian()
    r = room(walls=[[1.55, 0.0, 1.5, 0.25, 5.0, 1.5]])  # face at x = 1.3
    obs, info = reset_at(env, g, r, level(z=1.5, v=(1.5, 0.0, 0.0)))
    nominal = np.array([2.0, 0.3, 0.2, 0.5])
    pred = g.predict(env.unwrapped.get_state(), nominal, g.lap_guess)
    b, G, h = g.rows(pred)
    a = g.act(obs, {**info, "nominal_control": nominal})
    u = np.array([float(a[c][0]) for c in CONTROLS])
    assert a["active_ctrl"] == 1 and u[3] == 0.0
    wall = int(np.argmax(np.abs(G[:, 0])))
    assert G[wall] @ u[:3] == pytest.approx(h[wall], abs=1e-4)  # on the row
    assert u[0] < 2.0
    # the least change: the QP moved u only along the active row's normal
    np.testing.assert_allclose(np.cross(u[:3] - nominal[:3], G[wall]), 0.0, atol=1e-4)


@pytest.mark.parametrize("relaxed", [False, True])
def test_qpsolvers_backends_agree_with_the_direct_osqp_path(relaxed):
    """The same QP through qpsolvers (an interior-point and an active-set solver): the same
    command to the solvers' tolerance, on a strict problem (one wall row active) and on a relaxed
    one (two opposite walls)."""
    from rmm_guardians.cbf.backend import installed_solvers
    from rmm_guardians.cbf.quadrotor_rows import CommandQP

    lo, hi = np.array([-2.0, -2.0, -1.0]), np.array([2.0, 2.0, 1.0])
    G = np.array([[1 / TAU_H, 0.0, 0.0], [-1 / TAU_H, 0.0, 0.0]])
    h = np.array([-0.2, -0.2]) if relaxed else np.array([1.0, 5.0])
    u_nom = np.array([1.5, 0.5, 0.2])
    want = CommandQP(2, lo, hi, 1e3, 1e-6).solve(G, h, u_nom, relaxed=relaxed)
    assert want is not None and (
        want[0] == pytest.approx(0.0, abs=1e-5) if relaxed else want[0] == pytest.approx(TAU_H, abs=1e-5)
    )
    for name in {"clarabel", "daqp"} & set(installed_solvers()):
        got = CommandQP(2, lo, hi, 1e3, 1e-6, name=name).solve(G, h, u_nom, relaxed=relaxed)
        np.testing.assert_allclose(got, want, atol=1e-4, err_msg=name)
    assert CommandQP(2, lo, hi, 1e3, 1e-6).solve(G, np.array([-0.2, -0.2]), u_nom) is None  # strict: infeasible


def test_latency_prediction_is_the_closed_loop_flow(env):
    g = QuadrotorCBFGuardian()
    reset_at(env, g, room(), level(z=2.0, v=(1.0, 0.0, 0.0)))
    s = env.unwrapped.get_state()
    cmd = np.array([1.5, -0.5, 0.3, 0.2])
    want = ClosedLoopQuadrotor(CommandController()).propagate(s[None], cmd[None], 0.11, 2)[0, 1]
    np.testing.assert_array_equal(g.predict(s, cmd, 0.11), want)
    np.testing.assert_array_equal(g.predict(s, cmd * 10, 0.11), g.predict(s, np.clip(cmd * 10, g.lo, g.hi), 0.11))


@settings(max_examples=25, deadline=None)
@given(
    st.floats(-3.0, 3.0),
    st.floats(-3.0, 3.0),
    st.floats(0.6, 2.5),
    st.floats(-math.pi, math.pi),
    st.lists(st.floats(-2.0, 2.0), min_size=2, max_size=2),
    st.floats(-1.0, 1.0),
    st.lists(st.floats(-3.0, 3.0), min_size=4, max_size=4),
)
def test_decisions_keep_their_rows_and_the_box(x, y, z, yaw, vh, vz, nominal):
    """Whatever the state and the nominal command (even outside the box): the guardian either
    leaves control with the pilot, and then the nominal (clipped to the box) satisfies every
    row, or commands within the box and, unless recovering, satisfies every row."""
    r = room(
        walls=[[3.5, 0.0, 1.5, 0.25, 5.0, 1.5], [0.0, -3.5, 1.5, 5.0, 0.25, 1.5]],
        objects=[
            obj("sphere", [-1.5, 1.5, 0.6], [0.6]),
            obj("cylinder", [1.5, 1.8, 0.5], [0.4, 1.0]),
            obj("box", [-1.5, -1.5, 0.4], [0.4, 0.3, 0.4], quat_from_euler(0.0, 0.0, 0.7)),
        ],
    )
    g = QuadrotorCBFGuardian()
    g.reset(seed=0, action_space=SPACE, privileged=lambda: {"room": r, "state": level(), "sim_time": 0.0})
    state = level(x, y, z, yaw, (*vh, vz))
    nominal = np.array(nominal)
    a = g.decide(state, nominal)
    _, G, h = g.rows(state)
    if a["active_ctrl"] == 0:
        u = np.clip(nominal, g.lo, g.hi)
    else:
        u = np.array([float(a[c][0]) for c in CONTROLS])
        assert np.all(u >= g.lo) and np.all(u <= g.hi) and u[3] == 0.0
    if g.stats()["qp_fallbacks"] == 0:
        assert np.all(G @ u[:3] <= h + 1e-4)


SPACE = GuardianActionSpace.for_dynamics(
    ClosedLoopQuadrotor(CommandController()), CONTROLS, dynamics_name="quadrotor"
)  # the env's


def test_an_infeasible_qp_recovers_with_the_least_violation(env):
    """Between two walls 0.7 m apart the body (bounding radius 0.304, margin 0.05) is inside
    both margins: each row asks for a positive speed away from its wall, which no command meets.
    The recovery shares one slack over the rows: by symmetry it stops across the corridor and
    keeps the rest of the nominal."""
    g = QuadrotorCBFGuardian(predict_latency=False)
    r = room(walls=[[0.6, 0.0, 1.5, 0.25, 5.0, 1.5], [-0.6, 0.0, 1.5, 0.25, 5.0, 1.5]])  # faces at x = +-0.35
    obs, info = reset_at(env, g, r, level(z=1.5))
    b, G, h = g.rows(env.unwrapped.get_state())
    assert b[0] == b[1] == pytest.approx(0.35 - BOUND - g.margin) and h[0] < 0 and h[1] < 0
    a = g.act(obs, {**info, "nominal_control": np.array([1.0, 0.5, 0.0, 0.0])})
    u = np.array([float(a[c][0]) for c in CONTROLS])
    assert a["active_ctrl"] == 1 and g.stats()["qp_fallbacks"] == 1 and g.stats()["hover_fallbacks"] == 0
    assert u[0] == pytest.approx(0.0, abs=1e-4)  # yaw 0: forward = x, across the corridor
    assert u[1] == pytest.approx(0.5, abs=1e-3) and u[2] == pytest.approx(0.0, abs=1e-3)


def test_a_deadlock_follows_the_wall_and_turns_at_a_concave_corner(env):
    """The pilot pushes straight at a wall (face x = 1.3, the body 0.36 m from it, still),
    leaning a little to +y: the row lets through u_x <= p1 p2 b tau_h = 9 (0.36 - 0.304 - 0.05)
    0.42 = 0.023, so the filter alone would leave it under v_stuck (0.25 m/s).  The guardian then
    follows the wall on the side the nominal leans to at v_slide (1.5 m/s), the reference itself
    since it satisfies the rows.  With a second wall across the way (face y = 0.9) it turns to
    follow that one, keeping the walls on the same hand."""
    g = QuadrotorCBFGuardian(predict_latency=False)
    wall_a = [1.55, 0.0, 1.5, 0.25, 5.0, 1.5]
    obs, info = reset_at(env, g, room(walls=[wall_a]), level(x=0.94, z=1.5))
    a = g.act(obs, {**info, "nominal_control": np.array([1.5, 0.1, 0.0, 0.0])})
    np.testing.assert_allclose([float(a[c][0]) for c in CONTROLS], [0.0, 1.5, 0.0, 0.0], atol=1e-12)
    assert g.stats()["slides"] == 1 and g._side == -1
    obs, info = reset_at(env, g, room(walls=[wall_a, [0.0, 1.15, 1.5, 5.0, 0.25, 1.5]]), level(x=0.94, y=0.54, z=1.5))
    g._side = -1  # following wall A with it on the right, heading +y
    a = g.act(obs, {**info, "nominal_control": np.array([1.5, 0.1, 0.0, 0.0])})
    np.testing.assert_allclose([float(a[c][0]) for c in CONTROLS], [-1.5, 0.0, 0.0, 0.0], atol=1e-12)
    # free, but still pushing into the wall it follows: it keeps following
    obs, info = reset_at(env, g, room(walls=[wall_a]), level(x=0.3, z=1.5))
    g._side = -1
    a = g.act(obs, {**info, "nominal_control": np.array([0.2, 0.0, 0.0, 0.0])})
    np.testing.assert_allclose([float(a[c][0]) for c in CONTROLS], [0.0, 1.5, 0.0, 0.0], atol=1e-12)
    # free and pointing away from the wall: back to the pilot
    a = g.act(obs, {**info, "nominal_control": np.array([-1.0, -1.0, 0.0, 0.0])})
    assert a["active_ctrl"] == 0 and g._side == 0


def test_bad_input_is_named(env):
    g = QuadrotorCBFGuardian()
    obs, info = reset_at(env, g, room(), level(z=2.0))
    with pytest.raises(
        ValueError, match=r"info\['nominal_control'\].*but the step's info has none \(keys: \['sim_time'"
    ):
        g.act(obs, {"sim_time": 0.0})
    with pytest.raises(ValueError, match=r"must be 4 finite numbers .* got \[1.0, nan\]"):
        g.act(obs, {"nominal_control": [1.0, float("nan")]})
    for kwargs, msg in (
        ({"p1": 0}, "p1 .* > 0.0, got 0"),
        ({"tau_h": float("nan")}, "tau_h .* got nan"),
        ({"n_rows": 0}, "n_rows must be an integer >= 1"),
        ({"solver": "cplex"}, "solver must be 'osqp'"),
    ):
        with pytest.raises(ValueError, match=msg):
            QuadrotorCBFGuardian(**kwargs)
    from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv

    d4 = Dubins4DGuardedEnv()
    with pytest.raises(ValueError, match=r"guardian 'cbf' \(quadrotor\) models the quadrotor's velocity command"):
        g.check_spaces(d4.observation_space, d4.action_space)


def test_a_nan_state_hovers_and_is_counted(env):
    g = QuadrotorCBFGuardian()
    obs, info = reset_at(env, g, room(), level(z=2.0))
    g._privileged = lambda: {"state": np.full(13, np.nan), "sim_time": 0.1}
    a = g.act(obs, info)
    assert a["active_ctrl"] == 1 and not any(float(a[c][0]) for c in CONTROLS) and g.stats()["nan_states"] == 1


def test_a_fixed_clock_episode_it_saves():
    """An episode of ``QuadrotorRoomParallel-v0`` (fixed 1 ms clock) in which the pilot alone
    flies into the room and the filter brings it to the goal."""
    import gymnasium as gym

    outcomes = {}
    for name in ("inactive", "cbf"):
        e = gym.make("QuadrotorRoomParallel-v0", clock="fixed:1")
        g = make_guardian(name, env_id="QuadrotorRoomParallel-v0")
        obs, info = e.reset(seed=SAVED_SEED)
        g.reset(
            seed=0,
            observation_space=e.observation_space,
            action_space=e.action_space,
            privileged=e.unwrapped.privileged,
        )
        while True:
            obs, _, te, tr, info = e.step(g.act(obs, info))
            if te or tr:
                outcomes[name] = info["outcome"]
                break
        e.close()
    assert outcomes == {"inactive": "collision", "cbf": "goal"}


SAVED_SEED = 2
