import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

try:  # pybullet is pinned in the test extra: a missing install must fail loudly, not skip every test here
    import pybullet  # noqa: F401
except ImportError as e:
    raise ImportError(
        "the quadrotor tests need pybullet==3.2.7, part of the test extra: pip install -e '.[test]'"
    ) from e

from gymnasium.utils.env_checker import check_env

import rmm_envs  # noqa: F401
from rmm_envs.systems.quadrotor.body import QUADROTOR
from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv
from rmm_envs.systems.quadrotor.rooms import generate_room

EMPTY = {
    "n_rectangles": 1,
    "x_range": 10.0,
    "y_range": 10.0,
    "wall_height": 3.0,
    "n_boxes": 0,
    "n_cylinders": 0,
    "n_spheres": 0,
}


def open_spot(env):
    """The footprint cell farthest from the walls (a free column to fly in)."""
    room = env.room
    cells = np.argwhere(room.footprint)
    centre = cells.mean(axis=0)
    ij = cells[np.argmin(np.linalg.norm(cells - centre, axis=1))]
    return room.origin + (ij + 0.5) * room.cell


def make(damping=0.04, height=1.5, v=(0, 0, 0), quat=(0, 0, 0, 1), w=(0, 0, 0)):
    env = QuadrotorRoomEnv(linear_damping=damping, angular_damping=damping)
    env.reset(seed=0, options={"room": dict(EMPTY)})
    xy = open_spot(env)
    state = [xy[0], xy[1], height, *quat, *v, *w]
    obs, info = env.reset(seed=0, options={"room": env.room, "state": state})
    return env, obs, info


def run(env, action, seconds):
    out = None
    for _ in range(int(round(seconds / env.control_dt))):
        out = env.step(np.asarray(action, np.float32))
        if out[2] or out[3]:
            break
    return out


def test_hover_holds_the_state():
    env, _, info = make()
    s0 = info["state"]
    obs, r, te, tr, info = run(env, [QUADROTOR.hover_thrust, 0, 0, 0], 1.0)
    assert not te
    np.testing.assert_allclose(info["state"][:3], s0[:3], atol=1e-3)
    np.testing.assert_allclose(info["state"][7:], 0, atol=1e-3)


def test_free_drift_and_constant_climb_match_closed_form():
    env, _, info = make(damping=0.0, v=(0.5, -0.25, 0))
    s0 = info["state"]
    _, _, te, _, info = run(env, [QUADROTOR.hover_thrust, 0, 0, 0], 1.0)
    assert not te
    np.testing.assert_allclose(info["state"][:3], s0[:3] + np.array([0.5, -0.25, 0.0]) * info["sim_time"], atol=2e-3)
    env, _, info = make(damping=0.0, height=0.6)
    s0 = info["state"]
    a = 1.0
    _, _, te, _, info = run(env, [QUADROTOR.mass * (QUADROTOR.gravity + a), 0, 0, 0], 1.0)
    t = info["sim_time"]
    assert info["state"][2] == pytest.approx(s0[2] + 0.5 * a * t * t, abs=1e-2)  # semi-implicit Euler: O(dt)
    assert info["state"][9] == pytest.approx(a * t, abs=1e-3)


def test_torque_is_applied_in_the_body_frame():
    # rolled by +90 degrees about x, the body z axis points along world -y
    q = (math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4))
    env, _, _ = make(damping=0.0, quat=q, height=2.0)
    _, _, _, _, info = env.step(np.array([0.0, 0.0, 0.0, 0.1], np.float32))  # Mz = 0.1 N m for 1/24 s
    w = info["state"][10:13]
    expected = 0.1 / 0.004 * env.control_dt  # I_zz = 0.004
    np.testing.assert_allclose(w, [0.0, -expected, 0.0], atol=0.02 * expected)


def test_rays_read_the_floor_and_the_open_sky():
    env, obs, _ = make(height=1.2)
    assert obs[5] == pytest.approx(1.2, abs=1e-3)  # -z: the floor
    assert obs[4] == 100.0  # +z: nothing above
    assert np.all(obs[:4] < 10.0)  # +-x, +-y: walls of a room at most ~12 m across
    np.testing.assert_allclose(obs[6:10], [0, 0, 0, 1], atol=1e-7)


def test_falling_onto_the_floor_is_a_contact():
    env, _, _ = make(height=0.5)
    _, r, te, tr, info = run(env, [0, 0, 0, 0], 2.0)
    assert te and not tr and r == -1.0 and info["outcome"] == "collision"
    assert info["sim_time"] == pytest.approx(math.sqrt(2 * (0.5 - 0.05) / 9.81), abs=0.03)


def test_generator_is_deterministic_and_rooms_are_enclosed():
    a, b = generate_room(np.random.default_rng(4)), generate_room(np.random.default_rng(4))
    np.testing.assert_array_equal(a.walls, b.walls)
    np.testing.assert_array_equal(a.footprint, b.footprint)
    assert [o["shape"] for o in a.objects] == [o["shape"] for o in b.objects]
    for seed in range(10):
        r = generate_room(np.random.default_rng(seed))
        assert r.footprint.any() and len(r.walls) > 0
        # no footprint cell touches the grid border: walls surround it
        f = r.footprint
        assert not (f[0].any() or f[-1].any() or f[:, 0].any() or f[:, -1].any())
        assert all(r.in_footprint(o["pos"][None, :2])[0] for o in r.objects)


def test_same_seed_same_episode():
    def episode():
        env = QuadrotorRoomEnv()
        obs, _ = env.reset(seed=9)
        out = [obs]
        for _ in range(20):
            obs, r, te, tr, _ = env.step(np.array([5.0, 0.01, 0.0, 0.0], np.float32))
            out.append(obs)
            if te or tr:
                break
        return np.array(out)

    np.testing.assert_array_equal(episode(), episode())


def test_check_env_and_render():
    check_env(gym.make("QuadrotorRoom-v0", render_mode="rgb_array").unwrapped, skip_render_check=False)
    env = gym.make("QuadrotorRoom-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (240, 320, 3) and frame.std() > 5


def test_bad_input():
    env, _, _ = make()
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0, 0, 0]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(3))
    room = env.room
    xy = open_spot(env)
    with pytest.raises(ValueError, match="contact"):
        env.reset(seed=0, options={"room": room, "state": [xy[0], xy[1], 0.01, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="unit quaternion"):
        env.reset(seed=0, options={"room": room, "state": [xy[0], xy[1], 1.0, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0]})
    with pytest.raises(ValueError, match="13 finite"):
        env.reset(seed=0, options={"room": room, "state": [0.0] * 12})
    with pytest.raises(ValueError, match="room"):
        env.reset(seed=0, options={"room": "big"})
    with pytest.raises(ValueError, match="control_dt"):
        QuadrotorRoomEnv(control_dt=0.01)


def test_numpy_propagator_reproduces_pybullet():
    """The batched propagator the fast labeller needs, against PyBullet itself on random branches."""
    import pybullet as p

    from rmm_envs.systems.quadrotor.body import Quadrotor
    from rmm_envs.systems.quadrotor.pybullet_body import push_body
    from rmm_envs.systems.quadrotor.pybullet_body import urdf_path as _urdf_path

    c = p.connect(p.DIRECT)
    try:
        p.setGravity(0, 0, -QUADROTOR.gravity, physicsClientId=c)
        p.setTimeStep(QUADROTOR.dt, physicsClientId=c)
        b = p.loadURDF(_urdf_path(), [0, 0, 50], flags=p.URDF_USE_INERTIA_FROM_FILE, physicsClientId=c)
        p.changeDynamics(
            b, -1, linearDamping=QUADROTOR.linear_damping, angularDamping=QUADROTOR.angular_damping, physicsClientId=c
        )
        quad = Quadrotor()
        rng = np.random.default_rng(7)
        n = 24
        S = np.zeros((n, 13))
        S[:, 2] = 50.0
        q = rng.normal(size=(n, 4))
        S[:, 3:7] = q / np.linalg.norm(q, axis=1, keepdims=True)
        S[:, 7:10] = rng.uniform(-2, 2, (n, 3))
        S[:, 10:13] = rng.uniform(-2, 2, (n, 3))
        U = quad.sample_controls(rng, n)
        paths = quad.propagate(S, U, 2.0, 8)  # 7 segments of 69 physics steps, as the original
        assert paths.shape == (n, 8, 13)
        for i in range(n):
            p.resetBasePositionAndOrientation(b, S[i, :3].tolist(), S[i, 3:7].tolist(), physicsClientId=c)
            p.resetBaseVelocity(b, S[i, 7:10].tolist(), S[i, 10:13].tolist(), physicsClientId=c)
            for seg in range(7):
                push_body(p, c, b, U[i], 69)
                pos, orn = p.getBasePositionAndOrientation(b, physicsClientId=c)
                v, w = p.getBaseVelocity(b, physicsClientId=c)
                np.testing.assert_allclose(paths[i, seg + 1, :3], pos, atol=1e-6)
                np.testing.assert_allclose(
                    np.abs(paths[i, seg + 1, 3:7] @ np.array(orn)), 1.0, atol=1e-9
                )  # same rotation
                np.testing.assert_allclose(paths[i, seg + 1, 7:13], [*v, *w], atol=1e-5)
    finally:
        p.disconnect(physicsClientId=c)


def test_hover_in_the_numpy_propagator():
    from rmm_envs.systems.quadrotor.body import Quadrotor

    quad = Quadrotor()
    s = np.array([[1.0, 2.0, 3.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]])
    path = quad.propagate(s, np.array([[0.5 * 9.81, 0, 0, 0]]), 2.0, 8)
    np.testing.assert_allclose(path[0, -1], s[0], atol=1e-12)
    with pytest.raises(ValueError, match="shape"):
        quad.propagate(np.zeros((1, 12)), np.zeros((1, 4)), 1.0, 4)


def test_every_generated_shape_exists_in_pybullet():
    import pybullet as p

    env = QuadrotorRoomEnv()
    for seed in range(3):
        env.reset(seed=seed)
        n = sum(
            len(p.getCollisionShapeData(b, -1, physicsClientId=env.client))
            for b in range(1, p.getNumBodies(physicsClientId=env.client))
            if b != env.body
        )
        assert n == len(env.room.walls) + len(env.room.objects)


def test_risk_scene_hooks_and_agreement_with_pybullet():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    from benchmarks.perf_quadrotor import compare

    env = QuadrotorRoomEnv()
    agree = []
    for seed in range(2):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        states = env.sample_states(rng, 40)
        in_contact = []
        for s in states:  # sampled states are clear of the room (analytically; PyBullet nearly always agrees)
            env.set_state(s)
            in_contact.append(env.in_contact())
        assert np.mean(in_contact) <= 0.05
        controls = env.risk_scene().sample_controls(rng, 40)
        ours, _, pb_any, err = compare(env, states, controls)
        agree.append(np.mean(ours.any(1) == pb_any))
        assert err.max() < 1e-6  # identical trajectories until the first contact
    assert np.mean(agree) >= 0.95  # the benchmark measures >= 98% on 400 branches


def test_observe_states_matches_the_env_and_restores_it():
    env, obs, info = make(height=1.2)
    before = env.get_state()
    o = env.observe_states(info["state"][None])[0]
    np.testing.assert_allclose(o, obs, atol=1e-6)
    np.testing.assert_array_equal(env.get_state(), before)


def test_risk_label_on_the_quadrotor():
    from rmm_envs.wrappers import RiskLabel

    env = RiskLabel(QuadrotorRoomEnv(), branches=8, seed=0)
    _, info = env.reset(seed=0)
    assert 0.0 <= info["risk"] <= 1.0


def test_shipped_quadrotor_model():
    from rmm_guardians.lrmm.model import LRMMModel, default_model_path

    m = LRMMModel.load(default_model_path("QuadrotorRoom-v0"), env_id="QuadrotorRoom-v0", obs_dim=16)
    assert m.meta["metrics"]["train"]["n"] == 65536 and m.meta["metrics"]["test"]["n"] == 8192
    assert len(m.meta["split"]["test_configs"]) == 4
    assert m.meta["metrics"]["test"]["mae"] <= 0.010
    # upside down and fast, just above the floor, is riskier than level, slow and high up
    env, _, _ = make(height=2.5)
    xy = open_spot(env)
    calm = np.array([xy[0], xy[1], 2.5, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0])
    wild = np.array([xy[0], xy[1], 0.5, 1, 0, 0, 0, 0, 0, -3.0, 5.0, 0, 0])
    r_calm, r_wild = m.predict(env.observe_states(np.stack([calm, wild])))
    assert r_wild > r_calm


@settings(max_examples=60, deadline=None)
@given(
    shape=st.sampled_from(["box", "cylinder", "sphere"]),
    size=st.lists(st.floats(0.05, 2.0), min_size=3, max_size=3),
    direction=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(lambda v: math.hypot(*v) > 1e-3),
)
def test_the_bounding_sphere_holds_the_object_and_touches_it(shape, size, direction):
    """No point of the bounding sphere lies inside the object (in its own frame, so in any
    orientation), and the sphere touches the object at a corner (box) or on a rim (cylinder)."""
    from rmm_envs.systems.quadrotor.rooms import bounding_radius
    from rmm_guardians.hj.room import _object_sd

    size = np.array(size[: {"box": 3, "cylinder": 2, "sphere": 1}[shape]])
    r = bounding_radius(shape, size)
    u = np.array(direction) / math.hypot(*direction)
    assert _object_sd(shape, size, *(r * u)) >= -1e-12
    corner = (
        size
        if shape == "box"
        else np.array([size[0], 0.0, size[1] / 2] if shape == "cylinder" else [0.0, 0.0, size[0]])
    )
    assert math.sqrt(float(np.sum(corner * corner))) == pytest.approx(r, rel=1e-12)
    assert abs(_object_sd(shape, size, *corner)) < 1e-12
