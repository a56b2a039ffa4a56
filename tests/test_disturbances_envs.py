"""Disturbances applied by an env (issue 52), on Dubins4D: off is the same bits as before, each kind
changes what it should and nothing else, the same seed gives the same episode, and the draws do not
depend on what the agent does."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401  (registers the envs)
from rmm_envs.disturbances import BLOCK, DisturbanceError

ENV = "Dubins4DGuarded-v0"
SEED = 7


def _action(turn: float, accel: float, active: int = 1) -> dict:
    return {"active_ctrl": active, "turnrate_ctrl": np.array([turn]), "accel_ctrl": np.array([accel])}


#: a fixed guardian control sequence: the same commands whatever the env shows
COMMANDS = [_action(0.1 * np.sin(k / 5), 0.3 * np.cos(k / 7)) for k in range(40)]


def _run(disturbances=None, actions=COMMANDS, seed: int = SEED, env_id: str = ENV):
    env = gym.make(env_id, disturbances=disturbances).unwrapped
    obs, _ = env.reset(seed=seed)
    observations, states, controls = [obs], [env.true_state], []
    for a in actions:
        obs, _, terminated, truncated, info = env.step(a)
        observations.append(obs)
        states.append(info["state"])
        controls.append(info["control"])
        if terminated or truncated:
            break
    return env, np.array(observations), np.array(states), np.array(controls)


def test_off_is_the_undisturbed_env_bit_for_bit():
    _, o0, s0, c0 = _run(None)
    for off in ("", [], ()):
        env, o, s, c = _run(off)
        assert env.realisation is None and env.disturbances == ()
        assert np.array_equal(o, o0) and np.array_equal(s, s0) and np.array_equal(c, c0)


def test_observation_noise_leaves_the_true_trajectory_untouched():
    _, o0, s0, c0 = _run(None)
    _, o, s, c = _run("obs-noise.rays=0.5")
    assert np.array_equal(s, s0) and np.array_equal(c, c0)  # the world and the controls as before
    assert np.array_equal(o[:, :5], o0[:, :5])  # time, goal offset, heading, speed
    assert not np.array_equal(o[:, 5:], o0[:, 5:])
    assert o[:, 5:].min() >= 0.0 and o[:, 5:].max() <= 10.0


def test_a_rate_disturbance_moves_the_position_by_its_rate_times_the_time():
    """A uniform drift ``d`` (held for the episode) adds ``d t`` to x and y, exactly: heading and speed
    do not depend on the position, so they are the undisturbed ones."""
    env, _, s0, _ = _run(None)
    env, _, s, _ = _run("dyn-rate=0.3")
    d = env.realisation.rate(0.0, 4)
    assert np.all(np.abs(d[:2]) <= 0.3) and np.all(d[:2] != 0) and np.all(d[2:] == 0)
    n = min(len(s), len(s0))
    t = 0.1 * np.arange(n)
    assert np.array_equal(s[:n, 2:], s0[:n, 2:])
    np.testing.assert_allclose(s[:n, :2] - s0[:n, :2], t[:, None] * d[None, :2], rtol=0, atol=1e-9)


def test_a_gain_mismatch_scales_the_acceleration_the_car_gets():
    """Full acceleration from a known state: the speed grows by ``accel_gain * 0.5`` m/s^2 up to the
    plant's own top speed."""
    actions = [_action(0.0, 0.5)] * 30
    env = gym.make(ENV, disturbances="mismatch.accel_gain+v_max=0.3").unwrapped
    env.reset(seed=SEED, options={"state": [0.0, 0.0, 0.0, 0.0], "goal": [9.0, 9.0, 0.5], "obstacles": []})
    p = env.plant_parameters()
    assert p["turn_gain"] == 1.0 and p["accel_gain"] != 1.0 and p["v_max"] != 2.0
    speeds = []
    for a in actions:
        *_, info = env.step(a)
        speeds.append(info["state"][3])
    t = 0.1 * np.arange(1, 31)
    np.testing.assert_allclose(speeds, np.minimum(0.5 * p["accel_gain"] * t, p["v_max"]), atol=1e-12)
    np.testing.assert_array_equal(info["control"], [0.0, 0.5])  # the command; the plant's gain is its own


def test_a_delay_applies_the_command_of_k_steps_before():
    _, _, _, c = _run("act-delay=3")
    commanded = np.array([[a["turnrate_ctrl"][0], a["accel_ctrl"][0]] for a in COMMANDS[: len(c)]])
    np.testing.assert_array_equal(c[3:], commanded[:-3])
    np.testing.assert_array_equal(c[:3], np.repeat(commanded[:1], 3, axis=0))


def test_action_noise_and_gain_keep_the_control_within_its_bounds():
    _, _, _, c = _run("act-noise=2.0;act-gain=0.5")
    assert np.all(np.abs(c[:, 0]) <= 0.25) and np.all(np.abs(c[:, 1]) <= 0.5)
    commanded = np.array([[a["turnrate_ctrl"][0], a["accel_ctrl"][0]] for a in COMMANDS[: len(c)]])
    assert not np.array_equal(c, commanded)


@pytest.mark.parametrize(
    "spec",
    ["obs-noise=0.2@white", "ray-dropout=0.3", "obs-bias=0.5", "act-noise=0.2", "act-gain=0.3", "act-delay=2",
     "dyn-rate=0.3@white", "dyn-rate=0.3@periodic", "dyn-rate=0.3@step", "impulse=1.0", "mismatch=0.3"],
)  # fmt: skip
def test_every_kind_gives_the_same_bits_twice_and_keeps_the_start(spec):
    env0, o0, *_ = _run(None, actions=[])
    a = _run(spec)
    b = _run(spec)
    for x, y in zip(a[1:], b[1:], strict=True):
        assert np.array_equal(x, y)
    env, *_ = _run(spec, actions=[])
    assert np.array_equal(env.true_state, env0.true_state)  # the start is drawn as undisturbed
    assert np.array_equal(env.scene.obstacles, env0.scene.obstacles)


def test_the_draws_do_not_depend_on_what_the_agent_does():
    """Two agents on one episode (one lets the driver drive, the other steers) meet the same
    disturbance at every sim time."""
    spec = "dyn-rate=0.3@white;obs-noise=0.1;ray-dropout=0.2"
    lazy, *_ = _run(spec, actions=[_action(0.0, 0.0, active=0)] * 20)
    busy, *_ = _run(spec, actions=COMMANDS[:20])
    obs = np.full(17, 5.0, np.float32)
    for k in range(0, 300, 7):
        t = 0.1 * k
        assert np.array_equal(lazy.realisation.rate(t, 4), busy.realisation.rate(t, 4))
        assert np.array_equal(lazy.realisation.observation(obs, t), busy.realisation.observation(obs, t))


def test_unseeded_episodes_follow_the_seeded_one_without_repeating_it():
    env = gym.make(ENV, disturbances="dyn-rate=0.3").unwrapped
    env.reset(seed=SEED)
    first = env.realisation.rate(0.0, 4)
    env.reset()
    second = env.realisation.rate(0.0, 4)
    env.reset(seed=SEED)
    assert np.array_equal(env.realisation.rate(0.0, 4), first) and not np.array_equal(first, second)


def test_the_parallel_env_and_the_map_env_take_them_too():
    env = gym.make("Dubins4DParallel-v0", disturbances="obs-noise.rays=0.2", clock="fixed:1")
    env.reset(seed=SEED)
    assert env.unwrapped.realisation is not None
    env = gym.make("Dubins4DMapGuarded-v0", disturbances="dyn-rate=0.1")
    env.reset(seed=SEED)
    assert env.unwrapped.realisation is not None


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("dyn-rate.theta=0.1", ["'theta'", "x, y"]),
        ("mismatch.mass=0.1", ["'mass'", "turn_gain"]),
        ("obs-noise.lidar=0.1", ["'lidar'", "goal_offset"]),
        ("obs-noise=-1", ["negative"]),
    ],
)
def test_bad_input_is_refused_when_the_env_is_made(spec, words):
    with pytest.raises(DisturbanceError) as e:
        gym.make(ENV, disturbances=spec)
    assert "\n" not in str(e.value) and all(w in str(e.value) for w in words)


# ---------------------------------------------------------------- the maze car and the quadrotor

MAZE = "Dubins3DMazeGuarded-v0"
QUAD = "QuadrotorRoomGuarded-v0"


def _driver_steps(env_id: str, n: int) -> list:
    space = gym.make(env_id).unwrapped.action_space
    idle = {k: np.zeros(space[k].shape) for k in space.spaces if k != "active_ctrl"}
    return [{"active_ctrl": 0, **idle}] * n


@pytest.mark.parametrize(("env_id", "n"), [(MAZE, 60), (QUAD, 15)])
def test_maze_and_quadrotor_off_are_the_undisturbed_env_and_sensor_noise_leaves_the_world(env_id, n):
    actions = _driver_steps(env_id, n)
    _, o0, s0, c0 = _run(None, actions, env_id=env_id)
    _, o, s, c = _run("", actions, env_id=env_id)
    assert np.array_equal(o, o0) and np.array_equal(s, s0) and np.array_equal(c, c0)
    _, o, s, c = _run("obs-noise=0.3", actions, env_id=env_id)
    assert np.array_equal(s, s0) and np.array_equal(c, c0) and not np.array_equal(o, o0)


def test_the_maze_drift_moves_the_car_by_its_rate_times_the_time():
    actions = _driver_steps(MAZE, 40)
    _, _, s0, c0 = _run(None, actions, env_id=MAZE)
    env, _, s, c = _run("dyn-rate=0.5", actions, env_id=MAZE)
    d = env.realisation.rate(0.0, 3)
    n = min(len(s), len(s0), 5)  # the driver answers the drifted pose after the first step
    np.testing.assert_allclose(s[1] - s0[1], [d[0] * 0.1, d[1] * 0.1, 0.0], atol=1e-9)
    assert np.all(np.abs(d[:2]) <= 0.5) and d[2] == 0 and n == 5


def test_the_maze_mismatch_changes_the_car_s_speed():
    env = gym.make(MAZE, disturbances="mismatch.speed=0.3").unwrapped
    env.reset(seed=SEED)
    speed = env.plant_parameters()["speed"]
    x0 = env.true_state
    *_, info = env.step(_driver_steps(MAZE, 1)[0])
    moved = np.hypot(*(info["state"][:2] - x0[:2]))
    assert speed != 10.0 and abs(speed / 10.0 - 1) <= 0.3
    assert abs(moved - speed * 0.1) < 1e-3  # a turning path's chord is barely shorter than its arc


def test_the_maze_refuses_ray_dropouts_its_rays_have_no_maximum():
    with pytest.raises(DisturbanceError, match="no maximum range"):
        gym.make(MAZE, disturbances="ray-dropout=0.1")


def test_quadrotor_wind_lifts_the_body_and_a_mismatch_changes_its_mass_in_pybullet():
    actions = _driver_steps(QUAD, 10)
    _, _, s0, _ = _run(None, actions, env_id=QUAD)
    env, _, s, _ = _run("dyn-rate.vz=2.0", actions, env_id=QUAD)
    up = env.realisation.rate(0.0, 13)[9]
    assert up != 0 and np.sign(s[-1][2] - s0[-1][2]) == np.sign(up)
    env = gym.make(QUAD, disturbances="mismatch.mass=0.3").unwrapped
    env.reset(seed=SEED)
    mass = env.p.getDynamicsInfo(env.body, -1, physicsClientId=env.client)[0]
    assert mass == pytest.approx(env.plant_parameters()["mass"]) and mass != pytest.approx(env.params.mass)
    a = _run("act-noise=0.2;impulse=0.3", actions, env_id=QUAD)
    b = _run("act-noise=0.2;impulse=0.3", actions, env_id=QUAD)
    assert all(np.array_equal(x, y) for x, y in zip(a[1:], b[1:], strict=True))


# ---------------------------------------------------------------- the vector env


@pytest.mark.parametrize(
    "spec",
    [
        "obs-noise=0.1;act-delay=2;act-noise=0.1;dyn-rate=0.2@white;impulse=0.5",
        "mismatch=0.2;ray-dropout=0.1",
        "obs-noise=0.1@white",  # the sensors alone: the plant steps as undisturbed
    ],
)
def test_the_vector_env_is_the_single_envs_under_disturbances_too(spec):
    """Sub-env ``i`` after ``reset(seed=s)`` is the single env after ``reset(seed=s + i)`` bit for bit,
    across autoresets (each sub-env's later episodes draw as the single env's unseeded resets do)."""
    from gymnasium.utils.env_checker import data_equivalence

    n = 4
    vec = gym.make_vec(ENV, num_envs=n, vectorization_mode="vector_entry_point", clock="fixed:1", disturbances=spec)
    ref = gym.make_vec(ENV, num_envs=n, vectorization_mode="sync", clock="fixed:1", disturbances=spec)
    for x, y in zip(vec.reset(seed=5), ref.reset(seed=5), strict=True):
        assert data_equivalence(x, y, exact=True)
    rng = np.random.default_rng(0)
    ended, longest = 0, 0.0
    for t in range(400):
        a = {
            "active_ctrl": (rng.random(n) < (0.2 if t % 50 < 40 else 0.9)).astype(np.int64),
            "turnrate_ctrl": rng.uniform(-0.3, 0.3, (n, 1)).astype(np.float32),
            "accel_ctrl": rng.uniform(-0.5, 0.5, (n, 1)).astype(np.float32),
        }
        out, expected = vec.step(a), ref.step(a)
        for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), out, expected, strict=True):
            assert data_equivalence(x, y, exact=True), f"step {t}: {name} differs"
        ended += int(np.sum(out[2] | out[3]))
        longest = max(longest, float(np.max(out[4]["sim_time"])))
    assert ended >= 4
    assert longest > BLOCK * vec.unwrapped._single.step_dt  # a white stream's second block read too


# ---------------------------------------------------------------- what a guardian assumes


def test_hj_takes_its_disturbance_bound_from_the_run_when_asked():
    """``hj.disturbance="env"``: the HJ value is solved for the run's own ``dyn-rate`` bound (read
    from the env at every reset; 0 without one); a number stays that number."""
    from rmm_guardians.hj.guardian import env_disturbance_bound
    from rmm_guardians.registry import make_guardian

    assert env_disturbance_bound(["dyn-rate=0.2", "obs-noise=0.1"]) == 0.2
    assert env_disturbance_bound(["dyn-rate.y=0.3@white", "dyn-rate.x=0.1"]) == 0.3
    assert env_disturbance_bound(["impulse=1.0"]) == 0.0 == env_disturbance_bound([])
    for spec, expected in (("dyn-rate=0.25", 0.25), (None, 0.0)):
        env = gym.make(ENV, disturbances=spec).unwrapped
        env.reset(seed=SEED)
        g = make_guardian("hj", env_id=ENV, grid_n=[21, 21, 8, 5], cache=False, threads=1, disturbance="env")
        g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space,
                privileged=env.privileged)  # fmt: skip
        assert g.dynamics.d_max == expected
    assert "disturbances" not in env.privileged()  # an undisturbed env's privileged data is as before
    with pytest.raises(ValueError, match="disturbance"):
        make_guardian("hj", env_id=ENV, disturbance="wind")


# ---------------------------------------------------------------- datasets under sensor noise


def test_a_dataset_under_sensor_noise_keeps_states_and_labels_and_perturbs_the_rays(tmp_path, small_dataset):
    """``rmm-datagen --disturb obs-noise.rays=...``: the same states and labels as the undisturbed
    dataset (the noise draws from streams of its own), the rays perturbed within their range, the
    rest of the observation untouched; the same bits twice; dynamics kinds refused in one line."""
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    plain, _ = small_dataset
    cfg = dict(configs=8, samples_per_config=24, branches=6, depth=2, configs_per_shard=4, seed=11)
    noisy = []
    for name in ("a", "b"):
        out = tmp_path / name
        spec = DatagenConfig(**cfg, env_kwargs={"disturbances": ["obs-noise.rays=0.5"]})
        generate(spec, out, workers=1, progress=False)
        noisy.append(load_dataset(out))
    a, b = noisy
    assert np.array_equal(a.state, plain.state) and np.array_equal(a.risk, plain.risk)
    assert np.array_equal(a.obs[:, :5], plain.obs[:, :5]) and not np.array_equal(a.obs[:, 5:], plain.obs[:, 5:])
    assert a.obs[:, 5:].min() >= 0 and a.obs[:, 5:].max() <= 10 and np.array_equal(a.obs, b.obs)
    inside = (plain.obs[:, 5:] > 2) & (plain.obs[:, 5:] < 8)  # away from the clipping at 0 and 10
    assert abs(np.std((a.obs[:, 5:] - plain.obs[:, 5:])[inside]) - 0.5) < 0.05
    with pytest.raises(ValueError, match="sensor disturbances"):
        DatagenConfig(**cfg, env_kwargs={"disturbances": ["dyn-rate=0.1"]}).validate()
