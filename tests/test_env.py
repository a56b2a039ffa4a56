import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmm_envs  # noqa: F401
from rmm_envs.clocks import FixedLatencyClock
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv

INACTIVE = {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}


def act(u1, u2, active=1):
    return {
        "active_ctrl": active,
        "turnrate_ctrl": np.array([u1], np.float32),
        "accel_ctrl": np.array([u2], np.float32),
    }


def run_episode(env, seed, policy=lambda obs: INACTIVE, options=None):
    obs, info = env.reset(seed=seed, options=options)
    traj = [obs]
    while True:
        obs, r, te, tr, info = env.step(policy(obs))
        traj.append(obs)
        if te or tr:
            return np.array(traj), r, info


def test_check_env_blocking():
    check_env(gym.make("Dubins4DGuarded-v0").unwrapped)
    check_env(gym.make("Dubins4DGuarded-v0", render_mode="rgb_array").unwrapped, skip_render_check=False)


def test_check_env_parallel_with_fixed_clock():
    check_env(gym.make("Dubins4DParallel-v0", clock="fixed:2").unwrapped)
    env = gym.make("Dubins4DParallel-v0", clock="fixed:2")
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)


def test_make_with_module_prefix_and_vector():
    env = gym.make("rmm_envs:Dubins4DGuarded-v0")
    assert env.observation_space.shape == (17,)
    venv = gym.make_vec("Dubins4DGuarded-v0", num_envs=3)
    obs, info = venv.reset(seed=1)
    assert obs.shape == (3, 17)
    acts = {
        "active_ctrl": np.zeros(3, int),
        "turnrate_ctrl": np.zeros((3, 1), np.float32),
        "accel_ctrl": np.zeros((3, 1), np.float32),
    }
    obs, r, te, tr, info = venv.step(acts)
    assert obs.shape == (3, 17) and r.shape == (3,)
    venv.close()


def test_observation_layout():
    env = Dubins4DGuardedEnv()
    obs, info = env.reset(
        seed=0, options={"state": [1.0, 2.0, 0.0, 1.5], "goal": [4.0, 6.0, 0.5], "obstacles": [[6.0, 2.0, 1.0]]}
    )
    assert obs.dtype == np.float32 and obs.shape == (17,)
    assert obs[0] == 0.0
    assert obs[1:3].tolist() == [3.0, 4.0]
    assert obs[3] == 0.0 and obs[4] == 1.5
    assert obs[5] == pytest.approx(4.0)  # straight ahead to the circle at x = 5
    assert obs[5 + 6] == 10.0  # backwards: nothing
    np.testing.assert_array_equal(info["state"], [1.0, 2.0, 0.0, 1.5])


def test_same_seed_same_episode():
    a = run_episode(Dubins4DGuardedEnv(), 7)
    b = run_episode(Dubins4DGuardedEnv(), 7)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[2]["outcome"] == b[2]["outcome"]
    c = run_episode(Dubins4DGuardedEnv(), 8)
    assert c[0].shape != a[0].shape or not np.array_equal(c[0], a[0])


def test_replaying_a_scenario_from_options():
    env = Dubins4DGuardedEnv()
    env.reset(seed=11)
    p = env.privileged()
    opts = {"state": p["state"].tolist(), "goal": p["goal"].tolist(), "obstacles": p["obstacles"].tolist()}
    a = run_episode(Dubins4DGuardedEnv(), 11)
    b = run_episode(Dubins4DGuardedEnv(), 999, options=opts)
    np.testing.assert_allclose(a[0][:, 1:], b[0][:, 1:])


def test_partial_options_keep_the_rest_seeded():
    env = Dubins4DGuardedEnv()
    obs1, i1 = env.reset(seed=3, options={"obstacles": [[50.0, 50.0, 1.0]]})
    obs2, i2 = env.reset(seed=3, options={"obstacles": [[50.0, 50.0, 1.0]]})
    np.testing.assert_array_equal(obs1, obs2)
    assert env.privileged()["obstacles"].tolist() == [[50.0, 50.0, 1.0]]


def test_goal_reached_gives_plus_one():
    env = Dubins4DGuardedEnv()
    env.reset(options={"state": [0, 0, 0, 2.0], "goal": [0.4, 0, 0.3], "obstacles": [[0, 8, 1]]})
    obs, r, te, tr, info = env.step(act(0, 0))
    assert (r, te, tr, info["outcome"]) == (1.0, True, False, "goal")
    assert info["episode_stats"]["cum_reward"] == 1.0


def test_obstacle_first_then_goal_is_a_collision():
    env = Dubins4DGuardedEnv(step_dt=1.0)
    # obstacle at 0.4..0.6 m ahead, goal further along the same step's path
    env.reset(options={"state": [0, 0, 0, 2.0], "goal": [1.5, 0, 0.2], "obstacles": [[0.5, 0, 0.1]]})
    obs, r, te, tr, info = env.step(act(0, 0))
    assert (r, info["outcome"]) == (-1.0, "collision")


def test_goal_first_then_obstacle_is_a_goal():
    env = Dubins4DGuardedEnv(step_dt=1.0)
    env.reset(options={"state": [0, 0, 0, 2.0], "goal": [0.5, 0, 0.1], "obstacles": [[1.5, 0, 0.2]]})
    obs, r, te, tr, info = env.step(act(0, 0))
    assert (r, info["outcome"]) == (1.0, "goal")


def test_tie_is_a_collision():
    env = Dubins4DGuardedEnv(step_dt=1.0)
    env.reset(options={"state": [0, 0, 0, 2.0], "goal": [1.0, 0, 0.2], "obstacles": [[1.0, 0.0, 0.2]]})
    obs, r, te, tr, info = env.step(act(0, 0))
    assert (r, info["outcome"]) == (-1.0, "collision")


def test_timeout_truncates():
    env = Dubins4DGuardedEnv(max_episode_sim_time=1.0)
    env.reset(options={"state": [0, 0, 0, 0.0], "goal": [9, 9, 0.5], "obstacles": [[-9, -9, 1]]})
    for _ in range(10):
        obs, r, te, tr, info = env.step(act(0, -0.5))
    assert tr and not te and info["outcome"] == "timeout"
    ep = info["episode_stats"]
    assert ep["n_env_steps"] == 10 and ep["n_active_ctrl_env_steps"] == 10
    assert ep["active_ctrl_sim_time"] == pytest.approx(1.0) and ep["cum_sim_time"] == pytest.approx(1.0)
    assert ep["final_speed"] == 0.0
    with pytest.raises(RuntimeError, match="reset"):
        env.step(INACTIVE)


def test_info_reports_who_drove():
    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    _, _, _, _, info = env.step(INACTIVE)
    assert info["active"] is False and info["control"].shape == (2,)
    _, _, _, _, info = env.step(act(0.1, -0.2))
    assert info["active"] is True
    np.testing.assert_allclose(info["control"], [0.1, -0.2], atol=1e-7)
    assert info["sim_time"] == pytest.approx(0.2)


def test_out_of_bounds_controls_are_clipped():
    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    _, _, _, _, info = env.step(act(3.0, -9.0))
    np.testing.assert_allclose(info["control"], [0.25, -0.5])
    _, _, _, _, info = env.step({"active_ctrl": 1, "turnrate_ctrl": -1.0, "accel_ctrl": 0.7})  # scalars accepted
    np.testing.assert_allclose(info["control"], [-0.25, 0.5])


@pytest.mark.parametrize(
    "action, match",
    [
        (act(np.nan, 0), "turnrate_ctrl"),
        (act(0, np.inf), "accel_ctrl"),
        ({"active_ctrl": 2, "turnrate_ctrl": [0.0], "accel_ctrl": [0.0]}, "active_ctrl"),
        ({"active_ctrl": 1, "turnrate_ctrl": [0.0, 1.0], "accel_ctrl": [0.0]}, "turnrate_ctrl"),
        ({"active_ctrl": 1, "turnrate_ctrl": "fast", "accel_ctrl": [0.0]}, "turnrate_ctrl"),
        ({"active_ctrl": 1, "turnrate_ctrl": [0.0]}, "accel_ctrl"),
        ({"active_ctrl": 1, "turnrate_ctrl": [0.0], "accel_ctrl": [0.0], "boost": 1}, "boost"),
        (3, "dict"),
    ],
)
def test_bad_actions(action, match):
    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(action)


@pytest.mark.parametrize(
    "options, match",
    [
        ({"state": [0, 0, 0]}, "state"),
        ({"state": [0, 0, 0, 3.0]}, "speed"),
        ({"state": [0, 0, 0, np.nan]}, "state"),
        ({"state": [0, 0, 0, 1.0], "obstacles": [[0, 0, 1]]}, "inside obstacle 0 .* of option .obstacles."),
        ({"obstacles": [[0, 0, -1]]}, "radii"),
        ({"goal": [1, 1, 0]}, "radius"),
        ({"state": [0, 0, 0, 1], "goal": [0, 0, 1], "obstacles": [[5, 5, 1]]}, "inside option .goal."),
        ({"start": [0, 0, 0, 1]}, "unknown"),
    ],
)
def test_bad_reset_options(options, match):
    with pytest.raises(ValueError, match=match):
        Dubins4DGuardedEnv().reset(seed=0, options=options)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"step_dt": 0}, "step_dt"),
        ({"n_rays": 0}, "n_rays"),
        ({"obstacle_min_rad": -1}, "obstacle radii"),
        ({"render_mode": "ascii"}, "render_mode"),
        ({"n_path_points": 1}, "n_path_points"),
    ],
)
def test_bad_constructor_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Dubins4DGuardedEnv(**kwargs)


def test_generated_scenarios_are_valid():
    env = Dubins4DGuardedEnv()
    for seed in range(200):
        env.reset(seed=seed)
        p = env.privileged()
        s, g, o = p["state"], p["goal"], p["obstacles"]
        assert np.all(np.hypot(s[0] - o[:, 0], s[1] - o[:, 1]) > o[:, 2])
        assert math.hypot(s[0] - g[0], s[1] - g[1]) > g[2]
        assert not np.any(np.hypot(g[0] - o[:, 0], g[1] - o[:, 1]) + g[2] < o[:, 2])
        assert -math.pi <= s[2] < math.pi and 0 <= s[3] <= 2


def test_rgb_render():
    env = gym.make("Dubins4DGuarded-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (512, 512, 3) and frame.dtype == np.uint8
    colours = {tuple(c) for c in frame.reshape(-1, 3)[::7]}
    assert (214, 39, 40) in colours and (31, 119, 180) in colours  # obstacles, vehicle


def test_fixed_clock_counts_compute_time():
    env = Dubins4DGuardedEnv(clock=FixedLatencyClock(0.002))
    _, _, info = run_episode(env, 0)
    ep = info["episode_stats"]
    assert ep["cum_compute_time"] == pytest.approx(0.002 * ep["n_env_steps"])
    assert ep["avg_compute_time"] == pytest.approx(0.002)
