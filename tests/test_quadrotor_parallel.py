"""QuadrotorRoomGuarded-v0 / QuadrotorRoomParallel-v0: controller, pilot, closed-loop labels, contract."""

import math
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.systems.quadrotor.body import QUADROTOR, Quadrotor
from rmm_envs.systems.quadrotor.closed_loop import ClosedLoopQuadrotor
from rmm_envs.systems.quadrotor.control import (
    CommandController,
    HoverAndLevel,
    body_packed,
    body_step,
    heading_of,
    yaw_of,
)
from rmm_envs.systems.quadrotor.driver import WaypointPilot
from rmm_envs.systems.quadrotor.guarded import CONTROLS, QuadrotorRoomGuardedEnv, observation_layout
from rmm_envs.systems.quadrotor.room_collision import BOUND, RoomCollision
from rmm_envs.systems.quadrotor.rooms import Room
from rmm_envs.systems.quadrotor.rotations import quat_from_euler, quat_to_rot
from rmm_envs.systems.quadrotor.scene import QuadrotorCommandScene

CTRL = CommandController()
M, G = QUADROTOR.mass, QUADROTOR.gravity
IX, IY, IZ = QUADROTOR.inertia


def level(x=0.0, y=0.0, z=1.5, yaw=0.0, v=(0.0, 0.0, 0.0), w=(0.0, 0.0, 0.0)):
    return np.array([x, y, z, *quat_from_euler(0.0, 0.0, yaw), *v, *w])


# ---------------------------------------------------------------- controller, hand-computed
def test_hover_command_holds_a_level_still_body():
    np.testing.assert_allclose(CTRL.wrench(level(), [0, 0, 0, 0]), [M * G, 0, 0, 0], atol=1e-15)


def test_forward_command_pitches_the_body_forward_by_the_velocity_gain():
    u = CTRL.wrench(level(), [1.0, 0, 0, 0])
    theta = math.atan2(CTRL.k_v * 1.0, G)  # desired tilt: f = (2.5, 0, 9.81)
    # R = I, R_d = Ry(theta): e_R = (0, -sin theta, 0), M_y = I_y k_R sin theta; thrust m f . e_z = m g
    np.testing.assert_allclose(u, [M * G, 0.0, IY * CTRL.k_R * math.sin(theta), 0.0], atol=1e-12)


def test_the_command_is_in_the_heading_frame():
    # yawed by 90 degrees, "forward" is world +y: the same body-frame wrench as unyawed
    np.testing.assert_allclose(
        CTRL.wrench(level(yaw=math.pi / 2), [1.0, 0, 0, 0]), CTRL.wrench(level(), [1.0, 0, 0, 0]), atol=1e-12
    )


def test_horizontal_acceleration_is_limited_and_climb_adds_thrust():
    # 4 m/s of error at k_v = 2.5 asks for 10 m/s^2, limited to a_max_h = 5: tilt atan(5 / g)
    u = CTRL.wrench(level(v=(-2.0, 0, 0)), [2.0, 0, 0, 0])
    assert u[2] == pytest.approx(IY * CTRL.k_R * math.sin(math.atan2(CTRL.a_max_h, G)), abs=1e-12)
    assert CTRL.wrench(level(), [0, 0, 1.0, 0])[0] == pytest.approx(M * (G + CTRL.k_vz * 1.0))
    assert CTRL.wrench(level(v=(0, 0, 2.0)), [0, 0, -1.0, 0])[0] == pytest.approx(M * (G - CTRL.a_max_z))


def test_yaw_rate_command_and_moment_bounds():
    assert CTRL.wrench(level(), [0, 0, 0, 1.0])[3] == pytest.approx(IZ * CTRL.k_wz * 1.0)
    upside_down = np.array([0, 0, 2.0, 1.0, 0, 0, 0, 0, 0, 0, 50.0, -50.0, 0])
    u = CTRL.wrench(upside_down, [0, 0, 0, 0])
    assert u[0] == 0.0  # the body z axis points down: no thrust
    assert abs(u[1]) == 2.0 and abs(u[2]) == 2.0  # clipped to QUADROTOR.control_high


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-math.pi, math.pi),
    st.lists(st.floats(-2, 2), min_size=4, max_size=4),
    st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3),
    st.floats(-0.3, 0.3),
    st.floats(-0.3, 0.3),
)
def test_wrench_is_invariant_under_a_yaw_of_the_whole_state(yaw, cmd, vel, roll, pitch):
    q0 = quat_from_euler(roll, pitch, 0.3)
    s0 = np.array([0, 0, 1, *q0, *vel, 0.1, -0.2, 0.3])
    Rz = quat_to_rot(quat_from_euler(0, 0, yaw))
    from rmm_envs.systems.quadrotor.rotations import quat_mul

    s1 = s0.copy()
    s1[3:7] = quat_mul(quat_from_euler(0, 0, yaw), q0)
    s1[7:10], s1[10:13] = Rz @ s0[7:10], Rz @ s0[10:13]
    np.testing.assert_allclose(CTRL.wrench(s1, cmd), CTRL.wrench(s0, cmd), atol=1e-9)


def test_controller_arguments_are_checked():
    with pytest.raises(ValueError, match="k_v must be a finite number > 0, got 0"):
        CommandController(k_v=0)
    with pytest.raises(ValueError, match="a_max_z must be below gravity"):
        CommandController(a_max_z=10.0)
    with pytest.raises(ValueError, match="low <= 0 <= high"):
        CommandController(command_low=(0.5, -2, -1, -1))
    with pytest.raises(TypeError, match="needs a QuadrotorParams"):
        CommandController(params="heavy")


# ---------------------------------------------------------------- compiled loop vs numpy reference
def test_compiled_body_step_equals_the_numpy_propagator():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    s = np.column_stack([rng.uniform(-3, 3, (50, 3)), q, rng.uniform(-5, 5, (50, 3)), rng.uniform(-20, 20, (50, 3))])
    u = rng.uniform(QUADROTOR.control_low, QUADROTOR.control_high, (50, 4))
    ref = Quadrotor().step(s, u)
    b = body_packed(QUADROTOR)
    ours = np.array([body_step(s[i], u[i], b, np.empty(13)) for i in range(50)])
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-12)


def test_closed_loop_paths_equal_the_numpy_reference_and_stabilise():
    sys_ = ClosedLoopQuadrotor()
    rng = np.random.default_rng(0)
    s = np.array([[0, 0, 2.0, *quat_from_euler(0.3, -0.2, 1.0), 1.5, -1.0, 0.5, 1.0, -1.0, 0.5]] * 6)
    cmds = sys_.sample_controls(rng, 6)
    cmds[0] = 0.0
    cmds[1:4, 3] = 0.0  # no yaw rate: the heading frame stands still, so velocity is tracked
    a, b = sys_.propagate(s, cmds, 3.0, 4), sys_.propagate_numpy(s, cmds, 3.0, 4)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)
    end = a[0, -1]  # zero command: stopped and level after 3 s
    assert np.abs(end[7:13]).max() < 0.02 and quat_to_rot(end[3:7])[2, 2] > 0.9999
    # a command without yaw rate is tracked within the drag's steady-state error
    for i in range(1, 4):
        psi = heading_of(a[i, -1, 3:7])
        v = a[i, -1, 7:10]
        fwd, left = math.cos(psi) * v[0] + math.sin(psi) * v[1], -math.sin(psi) * v[0] + math.cos(psi) * v[1]
        np.testing.assert_allclose([fwd, left, v[2]], cmds[i, :3], atol=0.15)
    with pytest.raises(ValueError, match="states must have shape"):
        sys_.propagate(np.zeros((2, 12)), np.zeros((2, 4)), 1.0, 3)


# ---------------------------------------------------------------- pilot, hand-computed
def pilot(**kw):
    return WaypointPilot(CTRL.command_low, CTRL.command_high, **kw)


def test_pilot_flies_straight_at_the_waypoint_in_the_heading_frame():
    p = pilot()
    p.reset([[1.0, 0.0, 1.5]])
    np.testing.assert_allclose(p.command(level()), [1.0, 0, 0, 0], atol=1e-12)  # gain 1 x 1 m
    p.reset([[10.0, 0.0, 1.5]])
    np.testing.assert_allclose(p.command(level()), [1.5, 0, 0, 0], atol=1e-12)  # cruise speed
    p.reset([[0.0, 10.0, 3.5]])
    # world +y at 1.5 m/s is "left" for yaw 0; 2 m up -> climb speed 0.5; bearing error pi/2 -> yaw rate 2 x pi/2, clipped to 1
    np.testing.assert_allclose(p.command(level()), [0, 1.5, 0.5, 1.0], atol=1e-12)
    np.testing.assert_allclose(p.command(level(yaw=math.pi / 2)), [1.5, 0, 0.5, 0], atol=1e-12)


def test_pilot_passes_reached_waypoints_and_stops_turning_at_the_goal():
    p = pilot()
    p.reset([[0.3, 0.0, 1.5], [0.0, -5.0, 1.5]])
    cmd = p.command(level())
    assert p.index == 1 and cmd[1] == pytest.approx(-1.5)
    p.reset([[0.3, 0.0, 1.5]])  # the last waypoint is never passed; within reach: no turn
    assert p.command(level(yaw=2.0))[3] == 0.0 and p.index == 0


def test_pilot_bad_arguments():
    with pytest.raises(ValueError, match="cruise_speed must be a finite number > 0, got 0"):
        pilot(cruise_speed=0)
    with pytest.raises(ValueError, match=r"waypoints must be \(K >= 1, 3\) finite points, got shape \(2,\)"):
        pilot().reset([1.0, 2.0])


# ---------------------------------------------------------------- world geometry
def test_clearance_of_one_wall_and_one_sphere():
    room = Room(
        footprint=np.ones((2, 2), bool),
        origin=np.zeros(2),
        cell=1.0,
        wall_height=2.0,
        walls=np.array([[5.0, 0.0, 1.0, 0.25, 3.0, 1.0]]),
        objects=[
            {
                "shape": "sphere",
                "pos": np.array([0.0, 3.0, 0.5]),
                "quat": np.array([0, 0, 0, 1.0]),
                "size": np.array([0.5]),
            }
        ],
    )
    col = RoomCollision(room)
    assert col.clearance([2.0, 0.0, 1.0]) == pytest.approx(1.0 - BOUND)  # the floor is nearest
    assert col.clearance([4.0, 0.0, 1.5]) == pytest.approx(0.75 - BOUND)  # the wall's face at x = 4.75
    assert col.clearance([0.0, 1.5, 3.0]) == pytest.approx(math.hypot(1.5, 2.5) - 0.5 - BOUND)  # the sphere


# ---------------------------------------------------------------- the env
@pytest.fixture(scope="module")
def env():
    e = QuadrotorRoomGuardedEnv(clock="fixed:1")
    yield e
    e.close()


@pytest.mark.parametrize("env_id", ["QuadrotorRoomGuarded-v0", "QuadrotorRoomParallel-v0"])
def test_check_env_and_last_step_info(env_id):
    e = gym.make(env_id, clock="fixed:1")
    check_env(e.unwrapped, skip_render_check=True)
    e.reset(seed=1)
    inactive = e.action_space.inactive()
    for _ in range(2000):
        _, reward, term, trunc, info = e.step(inactive)
        if term or trunc:
            break
    assert info["outcome"] in ("goal", "collision", "timeout")
    assert reward == {"goal": 1.0, "collision": -1.0, "timeout": 0.0}[info["outcome"]]
    assert info["episode_stats"]["outcome"] == info["outcome"] and info["episode_stats"]["n_env_steps"] > 0
    e.close()


def test_spaces_come_from_the_controller(env):
    space = env.action_space
    assert space.controls == CONTROLS
    np.testing.assert_array_equal(space.control_low, CTRL.command_low)
    np.testing.assert_array_equal(space.control_high, CTRL.command_high)
    assert isinstance(space.safe_default, HoverAndLevel)
    assert env.observation_space.layout == observation_layout() and env.observation_space.shape == (23,)
    env.reset(seed=0)
    scene = env.risk_scene()
    assert isinstance(scene, QuadrotorCommandScene)
    np.testing.assert_array_equal(scene.control_low, space.control_low)


def test_observation_fields_match_the_state(env):
    obs, info = env.reset(seed=2)
    lay = env.observation_space.layout
    s = info["state"]
    np.testing.assert_allclose(obs[lay["orientation"]], s[3:7], atol=1e-6)
    psi = heading_of(s[3:7])
    off = env.goal - s[:3]
    np.testing.assert_allclose(
        obs[lay["goal_offset"]],
        [math.cos(psi) * off[0] + math.sin(psi) * off[1], -math.sin(psi) * off[0] + math.cos(psi) * off[1], off[2]],
        atol=1e-5,
    )
    # the start is level, so the down ray meets the floor at the body's height, or something nearer
    assert 0 < obs[lay["rays_vertical"]][1] <= s[2] + 1e-5
    np.testing.assert_allclose(env.observe_states(s[None])[0], obs, atol=1e-6)


def test_hover_and_level_keeps_the_body_in_place(env):
    _, info = env.reset(
        seed=4,
        options={
            "state": level(x=0, y=0, z=1.5, v=(1.0, 0.5, 0)),
            "waypoints": [[5, 0, 1.5]],
            "room": Room(
                footprint=np.ones((40, 40), bool),
                origin=np.array([-10.0, -10.0]),
                cell=0.5,
                wall_height=3.0,
                walls=np.array([[50.0, 50.0, 1.5, 0.25, 0.25, 1.5]]),
            ),
        },
    )
    space = env.action_space
    hover = space.active(space.safe_default.policy(space, np.random.default_rng(0))(None))
    for _ in range(40):  # 4 s
        _, _, term, trunc, info = env.step(hover)
        assert not (term or trunc)
    s = info["state"]
    assert np.linalg.norm(s[:2]) < 1.0 and abs(s[2] - 1.5) < 0.1 and np.abs(s[7:10]).max() < 0.05
    assert info["active"] and np.array_equal(info["control"], np.zeros(4))


def test_pilot_reaches_the_goal_in_an_empty_room(env):
    room = Room(
        footprint=np.ones((40, 40), bool),
        origin=np.array([-10.0, -10.0]),
        cell=0.5,
        wall_height=3.0,
        walls=np.array([[50.0, 50.0, 1.5, 0.25, 0.25, 1.5]]),
    )
    env.reset(seed=0, options={"room": room, "state": level(), "waypoints": [[3.0, 0.0, 1.5], [3.0, 3.0, 1.0]]})
    for _ in range(200):
        _, reward, term, trunc, info = env.step(env.action_space.inactive())
        if term or trunc:
            break
    assert info["outcome"] == "goal" and reward == 1.0
    assert 4.0 < info["sim_time"] < 12.0  # 6 m at <= 1.5 m/s, with turns


def test_flying_into_a_wall_is_a_collision(env):
    room = Room(
        footprint=np.ones((40, 40), bool),
        origin=np.array([-10.0, -10.0]),
        cell=0.5,
        wall_height=3.0,
        walls=np.array([[3.0, 0.0, 1.5, 0.25, 3.0, 1.5]]),
    )
    env.reset(seed=0, options={"room": room, "state": level(), "waypoints": [[6.0, 0.0, 1.5]]})
    for _ in range(100):
        _, reward, term, trunc, info = env.step(env.action_space.inactive())
        if term or trunc:
            break
    assert info["outcome"] == "collision" and reward == -1.0
    assert 2.0 < info["state"][0] < 2.75  # the body (radius 0.3) at the wall's face x = 2.75


def test_given_waypoints_and_states_must_lie_over_the_room_and_clear_of_it(env):
    room = Room(
        footprint=np.ones((20, 20), bool),
        origin=np.array([-5.0, -5.0]),
        cell=0.5,
        wall_height=3.0,
        walls=np.array([[3.0, 0.0, 1.5, 0.25, 1.0, 1.5]]),
    )
    for w, bad in (
        ([[2.0, 2.0, 1.0], [20.0, 0.0, 1.0]], 1),  # beyond the footprint
        ([[3.0, 0.0, 1.0]], 0),
    ):  # inside the wall
        with pytest.raises(
            ValueError, match=rf"option 'waypoints': point {bad} .* must lie over the footprint of option 'room'"
        ):
            env.reset(seed=0, options={"room": room, "waypoints": w})
    # the bounding sphere (0.304 m) in the floor: refused for any room, before one is looked at
    with pytest.raises(
        ValueError, match=r"option 'waypoints': point 0 \[2.0, 2.0, 0.2\] must lie higher than the body's"
    ):
        env.reset(seed=0, options={"room": room, "waypoints": [[2.0, 2.0, 0.2]]})
    with pytest.raises(
        ValueError, match=r"option 'state': the body at \[9.0, 0.0, 1.5\] is not over the footprint of option 'room'$"
    ):
        env.reset(seed=0, options={"room": room, "state": list(level(x=9.0))})
    # a point just clear of the floor is accepted, and it becomes the goal
    env.reset(seed=0, options={"room": room, "state": list(level()), "waypoints": [[-3.0, 0.0, BOUND + 0.01]]})
    np.testing.assert_array_equal(env.privileged()["goal"], [-3.0, 0.0, BOUND + 0.01])
    # generated rooms are redrawn until given waypoints fit: the episode's room holds them
    w = [[0.5, 0.5, 1.2]]
    env.reset(seed=3, options={"waypoints": w})
    assert env.room.in_footprint(np.array([[0.5, 0.5]]))[0] and RoomCollision(env.room).clearance(w[0]) > 0


def test_same_seed_same_episode():
    a, b = gym.make("QuadrotorRoomParallel-v0", clock="fixed:1"), gym.make("QuadrotorRoomParallel-v0", clock="fixed:1")
    for e in (a, b):
        e.reset(seed=11)
    rng = np.random.default_rng(0)
    for _ in range(30):
        act = a.action_space.sample() if rng.random() < 0.3 else a.action_space.inactive()
        oa, ra, ta, ua, ia = a.step(act)
        ob, rb, tb, ub, ib = b.step(act)
        np.testing.assert_array_equal(oa, ob)
        assert (ra, ta, ua) == (rb, tb, ub)
        if ta or ua:
            break
    a.close()
    b.close()


@pytest.mark.parametrize(
    "options, match",
    [
        ({"state": [0.0] * 12}, "option 'state' must be 13 finite numbers"),
        ({"state": [0, 0, 1, 0, 0, 0, 2.0, 0, 0, 0, 0, 0, 0]}, "is not a unit quaternion"),
        ({"state": list(level(z=0.01))}, "in contact with the room drawn from the seed"),
        (
            {"state": list(level(x=1000.0, y=1000.0))},
            r"the body at \[1000.0, 1000.0, 1.5\] is not over the footprint of the room",
        ),
        (
            {"waypoints": [[1000.0, 1000.0, 1.0]]},
            r"option 'waypoints' \[\[1000.0, 1000.0, 1.0\]\]: in none of 100 rooms",
        ),
        (
            {"waypoints": [[0.0, 0.0, -5.0]]},
            r"point 0 \[0.0, 0.0, -5.0\] must lie higher than the body's bounding radius \(0.304 m\)",
        ),
        ({"waypoints": [[1.0, 1.0, 2.0], [1.0, 1.0, 0.304]]}, r"point 1 \[1.0, 1.0, 0.304\] must lie higher than"),
        ({"waypoints": [[1.0, 2.0]]}, "option 'waypoints' must be a list of K >= 1 finite"),
        ({"waypoints": [[1.0, 2.0, np.nan]]}, "option 'waypoints' must be a list"),
        ({"room": 3}, "option 'room' must be a Room or a dict"),
        ({"wind": 1}, "unknown reset options"),
    ],
)
def test_bad_reset_options(env, options, match):
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"step_dt": 0}, "step_dt must be a finite number of seconds > 0, got 0"),
        ({"max_episode_sim_time": math.inf}, "max_episode_sim_time must be"),
        ({"n_waypoints": 0}, "n_waypoints must be an integer >= 1"),
        ({"altitude": (0.1, 2.0)}, r"altitude must be a pair \(min, max\)"),
        (
            {"altitude": (0.4, 0.7)},
            r"max > 0.804 \(a drawn waypoint keeps its bounding sphere 0.5 m above the floor\), got \(0.4, 0.7\)",
        ),
        ({"goal_radius": -1}, "goal_radius must be"),
        ({"cruise_speed": math.nan}, "cruise_speed must be"),
        ({"ray_range": 0}, "ray_range must be"),
        ({"clock": "sundial"}, "clock"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        QuadrotorRoomGuardedEnv(**kwargs)


@pytest.mark.parametrize(
    "action, match",
    [
        (
            {"active_ctrl": 1, "vforward_ctrl": [np.nan], "vleft_ctrl": [0], "vup_ctrl": [0], "yawrate_ctrl": [0]},
            "'vforward_ctrl' must be finite",
        ),
        (
            {"active_ctrl": 2, "vforward_ctrl": [0], "vleft_ctrl": [0], "vup_ctrl": [0], "yawrate_ctrl": [0]},
            "must be 0 or 1",
        ),
        ({"active_ctrl": 1, "vforward_ctrl": [0]}, "missing field 'vleft_ctrl'"),
    ],
)
def test_bad_actions_refused_before_the_world_moves(env, action, match):
    env.reset(seed=3)
    before = env.true_state
    with pytest.raises(ValueError, match=match):
        env.step(action)
    np.testing.assert_array_equal(env.true_state, before)


def test_sampled_states_are_clear_and_labels_are_seeded(env):
    from rmm_envs.risk import RiskEstimator

    env.reset(seed=5)
    states = env.sample_states(np.random.default_rng(0), 20)
    assert not env.risk_scene().state_failed(states).any()
    np.testing.assert_array_equal(states, env.sample_states(np.random.default_rng(0), 20))
    est = RiskEstimator(env.risk_scene(), branches=4, depth=1, horizon=0.5, n_steps=3)
    r1 = est.estimate(states, np.random.default_rng(1)).risk
    np.testing.assert_array_equal(r1, est.estimate(states, np.random.default_rng(1)).risk)
    assert ((r1 >= 0) & (r1 <= 1)).all()


# ---------------------------------------------------------------- guardians on the quadrotor
def floor_model():
    """A real LRMM network on the down ray alone (feature 9): risk = sigmoid(3 sigmoid(10 - 10 x)),
    about 0.5 high above the floor and 0.95 below 0.5 m."""
    from rmm_guardians.lrmm.model import LRMMModel

    meta = {"features": [9], "obs_dim": 23, "env_id": "QuadrotorRoomGuarded-v0", "activation": "sigmoid"}
    return LRMMModel([(np.array([[-10.0]]), np.array([10.0])), (np.array([[3.0]]), None)], [0.0], [1.0], meta)


def test_lrmm_applies_hover_and_level_while_the_risk_is_high_then_commits(env):
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    g = LRMMGuardian(
        model=floor_model(), threshold=0.7, strategies="Commit(steps=2)", env_id="QuadrotorRoomParallel-v0"
    )
    g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    obs = np.zeros(23, np.float32)
    obs[9] = 2.0
    sig = lambda x: 1 / (1 + math.exp(-x))  # noqa: E731
    assert g.act(obs, {})["active_ctrl"] == 0
    assert g.last_risk == pytest.approx(sig(3 * sig(10 - 20)))
    obs[9] = 0.3
    a = g.act(obs, {})
    assert a["active_ctrl"] == 1 and all(float(a[c][0]) == 0.0 for c in CONTROLS)
    assert g.last_risk == pytest.approx(sig(3 * sig(10 - 3)))
    obs[9] = 2.0
    assert [g.act(obs, {})["active_ctrl"] for _ in range(3)] == [1, 1, 0]  # two committed steps, then released


def test_lrmm_safe_action_needs_a_safe_default():
    from rmm_envs.autonomy import GuardianActionSpace
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    g = LRMMGuardian(model=floor_model(), threshold=0.7, strategies="")  # the core alone
    from rmm_envs.autonomy import ObservationBox

    bare = GuardianActionSpace(CONTROLS, CTRL.command_low, CTRL.command_high)  # no safe default
    box = ObservationBox(np.zeros(23, np.float32), np.ones(23, np.float32), observation_layout())
    with pytest.raises(
        ValueError, match="the core applies the env's safe default, and this env's action space states none"
    ):
        g.check_spaces(box, bare)
    g.check_spaces(
        box, GuardianActionSpace(CONTROLS, CTRL.command_low, CTRL.command_high, safe_default=HoverAndLevel())
    )


def test_brakes_is_hover_and_level_and_random_draws_commands_in_the_box(env):
    from rmm_guardians import make_guardian

    env.reset(seed=6)
    for name in ("brakes", "random"):
        g = make_guardian(name, env_id="QuadrotorRoomParallel-v0")
        g.reset(seed=1, observation_space=env.observation_space, action_space=env.action_space)
        acts = [g.act(np.zeros(23, np.float32), {}) for _ in range(50)]
        u = np.array([[float(a[c][0]) for c in CONTROLS] for a in acts])
        assert (u >= CTRL.command_low).all() and (u <= CTRL.command_high).all()
        if name == "brakes":
            assert all(a["active_ctrl"] == 1 for a in acts) and not u.any()
        else:
            assert 0 < sum(a["active_ctrl"] for a in acts) < 50 and u.std(axis=0).min() > 0.1


def test_lrmm_reads_the_shipped_command_model_by_env_id(env):
    from rmm_guardians import make_guardian
    from rmm_guardians.lrmm.model import SHIPPED

    g = make_guardian("lrmm", env_id="QuadrotorRoomParallel-v0")
    ship = SHIPPED["QuadrotorRoomParallel-v0"]
    assert g.model.path.name == ship.files["act"] == "quadrotor_cmd_act.npz"
    from rmm_guardians.lrmm.decision import decision_path, read_decision
    from rmm_guardians.lrmm.strategies import Commit, RatedDriver, SafestCandidate, Slide

    decision = read_decision(decision_path(g.model.path))  # the file beside the model, with how it was chosen
    assert decision.strategies == (
        "RatedDriver(margin=0.15, still=0.05, stay=True), Commit(steps=20), SafestCandidate(), Slide()"
    )
    assert (g.threshold, g.threshold_source) == (decision.threshold, "stored decision") == (0.2, "stored decision")
    np.testing.assert_array_equal(g.model.candidates, [[0, 0, 0, 0], [0, 0, 1, 0], [-1.5, 0, 0, 0], [-1, 0, 1, 0]])
    assert g.model.meta["env_id"] == "QuadrotorRoomGuarded-v0" and g.model.obs_dim == 23
    risk_only = make_guardian(
        "lrmm", model=str(g.model.path.with_name(ship.files["risk"])), strategies="", threshold=0.5
    )
    assert risk_only.model.candidates is None and risk_only.model.meta["env_id"] == "QuadrotorRoomGuarded-v0"
    lay = env.observation_space.layout
    # it reads the rays, the heading-frame velocity and the body rates: not the yaw-dependent
    # quaternion nor the goal
    used = {f for f, a, b in lay.fields if any(a <= i < b for i in g.model.features)}
    assert used == {"rays", "rays_vertical", "velocity", "angular_velocity"}
    # acts on the pilot's command, rated against the best candidate and against holding still; slides by climbing
    assert g.strategies == (
        RatedDriver(margin=0.15, still=0.05, stay=True),
        Commit(steps=20),
        SafestCandidate(),
        Slide(),
    )
    obs, info = env.reset(seed=0)
    g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    a = g.act(obs, info)
    assert a["active_ctrl"] in (0, 1) and 0.0 < g.last_risk < 1.0 and 0.0 < g.signals()["risk_driver"] < 1.0


@pytest.mark.heavy
def test_rmm_bench_set_runs_every_default_guardian_on_the_quadrotor(tmp_path, capsys):
    import sqlite3

    from rmm_bench.cli import main as bench_main

    assert (
        bench_main(
            [
                "--env",
                "QuadrotorRoomParallel-v0",
                "--agent",
                "all",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--out",
                str(tmp_path),
                "--no-progress",
                "--no-figure",
                "--clock",
                "fixed:1",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "does not apply" not in err  # every default guardian applies to the quadrotor
    con = sqlite3.connect(tmp_path / "results.db")
    ran = {r[0] for r in con.execute("select agent from runs")}
    con.close()
    assert ran == {"lrmm", "cbf", "hj", "random", "inactive", "brakes"}


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3))
def test_clearance_is_one_lipschitz(p, dp):
    """What lets the env skip contact queries: the gap cannot shrink faster than the body moves."""
    room = Room(
        footprint=np.ones((2, 2), bool),
        origin=np.zeros(2),
        cell=1.0,
        wall_height=2.0,
        walls=np.array([[1.0, 0.0, 1.0, 0.25, 3.0, 1.0], [-2.0, 1.0, 0.5, 1.0, 0.25, 0.5]]),
        objects=[
            {
                "shape": "box",
                "pos": np.array([0.0, -2.0, 0.3]),
                "quat": np.array([0, 0, 0, 1.0]),
                "size": np.array([0.3, 0.3, 0.3]),
            }
        ],
    )
    col = RoomCollision(room)
    p0 = np.array(p) + [0, 0, 3.5]
    assert col.clearance(p0) - col.clearance(p0 + dp) <= np.linalg.norm(dp) + 1e-12


def test_skipping_contact_queries_changes_nothing():
    """The same episodes with a contact query after every physics step (no skipping)."""
    runs = []
    for skip in (True, False):
        e = QuadrotorRoomGuardedEnv(clock="fixed:1")
        if not skip:
            e._a_bound = math.inf  # the travel bound is infinite: every step is queried
        out = []
        for seed in (0, 1, 2, 3):
            e.reset(seed=seed)
            while True:
                _, r, te, tr, info = e.step(e.action_space.inactive())
                if te or tr:
                    break
            out.append((info["outcome"], e._physics_steps, info["state"].tolist()))
        e.close()
        runs.append(out)
    assert runs[0] == runs[1] and {o for o, _, _ in runs[0]} >= {"collision"}


def test_generated_rooms_are_those_the_shipped_datasets_were_made_from():
    """A fingerprint of the rooms of seeds 0-9, taken before generate_room was sped up: the
    shipped quadrotor datasets' rooms must not change."""
    import hashlib

    from rmm_envs.systems.quadrotor.rooms import generate_room

    h = hashlib.sha256()
    for seed in range(10):
        r = generate_room(np.random.default_rng(seed))
        h.update(np.ascontiguousarray(r.walls).tobytes())
        h.update(r.footprint.tobytes())
        for o in r.objects:
            h.update(o["shape"].encode())
            for k in ("pos", "quat", "size"):
                h.update(np.ascontiguousarray(o[k], dtype=float).tobytes())
    assert h.hexdigest() == "eb5280bcd4f648face1e5a8b4af3715159889846c9ae3258d941f28203c16cc2"


def test_lrmm_head_picks_the_lowest_risk_command_of_four_controls(env):
    """A real network with a two-candidate head on the down ray: risk sigmoid(3 h), hover
    sigmoid(2 h), climb sigmoid(-2 h) with h = sigmoid(10 - 10 x): climbing is rated safer."""
    from rmm_guardians.lrmm.guardian import LRMMGuardian
    from rmm_guardians.lrmm.model import LRMMModel

    meta = {
        "features": [9],
        "obs_dim": 23,
        "env_id": "QuadrotorRoomGuarded-v0",
        "activation": "sigmoid",
        "candidates": [[0, 0, 0, 0], [0, 0, 1, 0]],
        "candidate_hold": 1.0,
    }
    model = LRMMModel(
        [(np.array([[-10.0]]), np.array([10.0])), (np.array([[3.0], [2.0], [-2.0]]), None)], [0.0], [1.0], meta
    )
    g = LRMMGuardian(model=model, threshold=0.4, strategies="SafestCandidate")
    g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    obs = np.zeros(23, np.float32)
    obs[9] = 0.5
    a = g.act(obs, {})
    assert a["active_ctrl"] == 1 and [float(a[c][0]) for c in CONTROLS] == [0.0, 0.0, 1.0, 0.0]


def test_lrmm_built_for_another_env_or_without_a_head_says_how_to_serve_the_quadrotor(env):
    import warnings

    from rmm_guardians import make_guardian
    from rmm_guardians.lrmm.guardian import REMEDY, LRMMGuardian
    from rmm_guardians.lrmm.model import default_model_path

    spaces = {"observation_space": env.observation_space, "action_space": env.action_space}
    with pytest.raises(ValueError) as e:
        make_guardian("lrmm").reset(seed=0, **spaces)  # built for Dubins4D (no env_id)
    assert str(e.value) == (
        "guardian 'lrmm': the LRMM model (trained on Dubins4DCircles-v0) expects observations "
        "of shape (17,), the env's observation space is (23,)" + REMEDY
    )
    risk_path = default_model_path("QuadrotorRoomParallel-v0", variant="risk")
    with pytest.raises(ValueError, match="quadrotor_cmd.npz has no decision"):  # the risk-only model has none
        LRMMGuardian(env_id="QuadrotorRoomParallel-v0", model=risk_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a threshold given: nothing falls back
        risk_only = LRMMGuardian(env_id="QuadrotorRoomParallel-v0", model=risk_path, threshold=0.5)
        braking = LRMMGuardian(
            env_id="QuadrotorRoomParallel-v0", model=risk_path, threshold=0.5, strategies="BrakeTurn"
        )
    assert risk_only.strategies == ()  # no head, nothing stored: the core alone, which serves the quadrotor
    risk_only.reset(seed=0, **spaces)
    with pytest.raises(
        ValueError,
        match=r"strategy BrakeTurn needs the Dubins car's two controls, got 4 .*this env states a safe default "
        r"\(hover and level.*\), which the core alone applies",
    ):
        braking.reset(seed=0, **spaces)
    with pytest.raises(ValueError, match=r"strategy SafestCandidate reads the model's action-conditioned head"):
        LRMMGuardian(env_id="QuadrotorRoomParallel-v0", model=risk_path, threshold=0.5, strategies="SafestCandidate")
    for bad, shown in ((True, "True"), ("nan", "'nan'"), ("0.2", "'0.2'")):
        with pytest.raises(ValueError) as e:
            LRMMGuardian(env_id="QuadrotorRoomParallel-v0", threshold=bad)
        assert str(e.value) == f"threshold must be a number in [0, 1], got {shown}"


@pytest.mark.parametrize("env_id", ["QuadrotorRoomGuarded-v0", "QuadrotorRoom-v0"])
def test_labelling_hooks_refuse_bad_states_and_counts_by_name(env_id):
    e = gym.make(env_id).unwrapped
    e.reset(seed=0)
    good = e.sample_states(np.random.default_rng(0), 2)
    for states, text in (
        (np.zeros((3, 5)), r"states must have shape \(N, 13\), got shape \(3, 5\)"),
        (good[0], r"states must have shape \(N, 13\), got shape \(13,\)"),
        (np.vstack([good[0], np.full(13, np.nan)]), r"states must be finite: row 1 is \[nan"),
        (
            np.vstack([good[0], np.r_[good[0, :3], np.zeros(4), good[0, 7:]]]),
            r"states: row 1 has the quaternion \[0.0, 0.0, 0.0, 0.0\], not a unit quaternion",
        ),
    ):
        with pytest.raises(ValueError, match=text):
            e.observe_states(states)
    for n in (1.5, -1, True):
        with pytest.raises(ValueError, match=rf"to draw must be an integer >= 0, got {n!r}"):
            e.sample_states(np.random.default_rng(0), n)
    assert e.sample_states(np.random.default_rng(0), 0).shape == (0, 13)
    e.close()


@pytest.mark.parametrize(
    "room, text",
    [
        ({"x_range": math.nan}, "x_range must be a finite number of metres > 0, got nan"),
        ({"wall_height": math.inf}, "wall_height must be a finite number of metres > 0, got inf"),
        ({"n_rectangles": "a"}, "n_rectangles must be an integer >= 1, got 'a'"),
        ({"n_boxes": 1.7}, "n_boxes must be an integer >= 0, got 1.7"),
        ({"n_spheres": True}, "n_spheres must be an integer >= 0, got True"),
    ],
)
def test_bad_generate_room_arguments_in_reset_options_are_named(env, room, text):
    with pytest.raises(ValueError, match=re.escape(f"generate_room: {text}")):
        env.reset(seed=0, options={"room": room})


@settings(max_examples=50, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1.2, 1.2), st.floats(-1.2, 1.2))
def test_scalar_yaw_equals_the_batched_heading(yaw, roll, pitch):
    q = quat_from_euler(roll, pitch, yaw)
    assert abs(yaw_of(*q) - float(heading_of(q))) < 1e-12
    assert abs(math.remainder(yaw_of(*quat_from_euler(0.0, 0.0, yaw)) - yaw, 2 * math.pi)) < 1e-12
