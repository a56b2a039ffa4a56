"""The native vector env of Dubins4DGuarded-v0 against Gymnasium's SyncVectorEnv of single envs."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode

import rmm_envs  # noqa: F401
from rmm_envs.systems.dubins4d.vector import Dubins4DCirclesVectorEnv

ID = "Dubins4DGuarded-v0"


def _pair(n, mode=AutoresetMode.NEXT_STEP, **kw):
    vec = gym.make_vec(
        ID, num_envs=n, vectorization_mode="vector_entry_point", autoreset_mode=mode, clock="fixed:1", **kw
    )
    ref = gym.make_vec(
        ID, num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}, clock="fixed:1", **kw
    )
    return vec, ref


def _actions(vec, rng, p_active):
    """Seeded actions (all drawn from ``rng``, so a test is the same on every run); out-of-bounds
    values are clipped by both envs."""
    n = vec.num_envs
    return {
        "active_ctrl": (rng.random(n) < p_active).astype(np.int64),
        "turnrate_ctrl": rng.uniform(-0.4, 0.4, (n, 1)).astype(np.float32),
        "accel_ctrl": rng.uniform(-0.5, 0.5, (n, 1)).astype(np.float32),
    }


def _assert_same(out_vec, out_ref, t):
    # a step's five values, or reset's two (obs, info): then zip stops after the first two names
    for name, x, y in zip(("obs", "reward", "terminated", "truncated", "info"), out_vec, out_ref, strict=False):
        assert data_equivalence(x, y, exact=True), f"step {t}: {name} differs:\n{x}\n{y}"


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_bit_for_bit_equal_to_single_envs_across_autoresets(mode):
    """Sub-env i after reset(seed=s) is the single env after reset(seed=s + i): observations,
    rewards, terminations and every info entry exactly equal, step for step, over many
    episodes (autoresets), with the guardian active in some sub-envs and not in others."""
    n, steps = 6, 700
    vec, ref = _pair(n, mode)
    assert type(vec.unwrapped) is Dubins4DCirclesVectorEnv
    _assert_same(vec.reset(seed=11), ref.reset(seed=11), "reset")
    rng = np.random.default_rng(0)
    ended = active = inactive = 0
    for t in range(steps):
        a = _actions(vec, rng, p_active=0.1 if t % 50 < 40 else 0.9)
        out = vec.step(a)
        _assert_same(out, ref.step(a), t)
        ended += int(np.sum(out[2] | out[3]))
        active += int(np.sum(a["active_ctrl"]))
        inactive += int(np.sum(1 - a["active_ctrl"]))
    assert ended >= 15 and active > 500 and inactive > 2000, (ended, active, inactive)


def test_outcomes_include_goal_collision_and_timeout():
    """A longer inactive run: all three outcomes occur and agree with the single envs."""
    n = 4
    vec, ref = _pair(n, max_episode_sim_time=15.0)
    _assert_same(vec.reset(seed=0), ref.reset(seed=0), "reset")
    a = {
        "active_ctrl": np.zeros(n, np.int64),
        "turnrate_ctrl": np.zeros((n, 1), np.float32),
        "accel_ctrl": np.zeros((n, 1), np.float32),
    }
    seen = set()
    for t in range(1500):
        out = vec.step(a)
        _assert_same(out, ref.step(a), t)
        if "outcome" in out[4]:
            seen |= set(out[4]["outcome"][out[4]["_outcome"]])
            assert set(out[4]["episode_stats"]["outcome"][out[4]["_episode_stats"]]) <= {"goal", "collision", "timeout"}
        if seen == {"goal", "collision", "timeout"}:
            break
    assert seen == {"goal", "collision", "timeout"}


def test_disabled_autoreset_with_reset_mask():
    n = 3
    vec, ref = _pair(n, AutoresetMode.DISABLED)
    _assert_same(vec.reset(seed=5), ref.reset(seed=5), "reset")
    rng = np.random.default_rng(1)
    resets = 0
    for t in range(400):
        a = _actions(vec, rng, 0.2)
        out = vec.step(a)
        _assert_same(out, ref.step(a), t)
        done = out[2] | out[3]
        if done.any():
            resets += 1
            with pytest.raises(RuntimeError, match=f"sub-env {int(np.argmax(done))}'s episode has ended"):
                vec.step(a)
            _assert_same(
                vec.reset(options={"reset_mask": done.copy()}), ref.reset(options={"reset_mask": done.copy()}), t
            )
    assert resets >= 3


def test_seeding_convention_and_lists():
    vec = gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point")
    single = gym.make(ID)
    obs, info = vec.reset(seed=[7, None, 9])
    for i, s in ((0, 7), (2, 9)):
        o, inf = single.reset(seed=s)
        assert np.array_equal(obs[i], o) and np.array_equal(info["state"][i], inf["state"])
    obs2, _ = vec.reset(seed=40)
    assert np.array_equal(obs2[1], single.reset(seed=41)[0])
    # seed=None later keeps each sub-env's generator: the next episodes are the single env's next ones
    single.reset(seed=40)
    nxt = single.reset()[0]
    assert np.array_equal(vec.reset()[0][0], nxt)
    with pytest.raises(ValueError, match="seed must be None, an int or a list of 3"):
        vec.reset(seed=[1, 2])


def test_spaces_and_metadata():
    vec = gym.make_vec(ID, num_envs=5, vectorization_mode="vector_entry_point")
    single = gym.make(ID)
    assert vec.single_observation_space == single.observation_space
    assert vec.single_action_space == single.action_space
    assert vec.observation_space.shape == (5, 17)
    assert vec.action_space["active_ctrl"].nvec.tolist() == [2] * 5
    assert vec.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    obs, _ = vec.reset(seed=0)
    vec.action_space.seed(0)
    assert obs in vec.observation_space
    for _ in range(20):
        obs, r, te, tr, info = vec.step(vec.action_space.sample())
        assert obs in vec.observation_space and r.dtype == np.float64 and te.dtype == tr.dtype == np.bool_
    # the default vectorisation mode is the native one (the spec has a vector entry point)
    assert type(gym.make_vec(ID, num_envs=2).unwrapped) is Dubins4DCirclesVectorEnv


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("active_ctrl", np.array([0, 2]), "'active_ctrl' of sub-env 1 must be 0 or 1"),
        ("active_ctrl", np.array([0.5, 0]), "'active_ctrl' of sub-env 0 must be 0 or 1"),
        ("turnrate_ctrl", np.array([[0.0], [np.nan]]), "'turnrate_ctrl' of sub-env 1 must be finite"),
        ("accel_ctrl", np.zeros(3), r"'accel_ctrl' must be 2 numbers, shape \(2,\) or \(2, 1\)"),
        ("accel_ctrl", np.array(["a", "b"]), "'accel_ctrl' must be 2 numbers"),
    ],
)
def test_bad_actions_name_the_field_and_sub_env(field, value, match):
    vec = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point")
    vec.reset(seed=0)
    a = {"active_ctrl": np.zeros(2, np.int64), "turnrate_ctrl": np.zeros((2, 1)), "accel_ctrl": np.zeros((2, 1))}
    a[field] = value
    with pytest.raises(ValueError, match=match):
        vec.step(a)


def test_bad_action_containers_and_arguments():
    vec = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point")
    with pytest.raises(RuntimeError, match="call reset"):
        vec.step({"active_ctrl": np.zeros(2), "turnrate_ctrl": np.zeros(2), "accel_ctrl": np.zeros(2)})
    vec.reset(seed=0)
    with pytest.raises(ValueError, match="missing field 'accel_ctrl'"):
        vec.step({"active_ctrl": np.zeros(2), "turnrate_ctrl": np.zeros(2)})
    with pytest.raises(ValueError, match=r"unknown fields \['brake'\]"):
        vec.step({"active_ctrl": np.zeros(2), "turnrate_ctrl": np.zeros(2), "accel_ctrl": np.zeros(2), "brake": 1})
    with pytest.raises(ValueError, match="must be a dict of arrays"):
        vec.step(3)
    with pytest.raises(ValueError, match="reset_mask"):
        vec.reset(options={"reset_mask": np.array([1, 0])})
    with pytest.raises(ValueError, match="at least one"):
        vec.reset(options={"reset_mask": np.zeros(2, bool)})
    before = vec.reset(seed=0)[0]
    with pytest.raises(ValueError, match="must hold n_obstacles = 5"):
        vec.reset(seed=1, options={"obstacles": [[0.0, 0.0, 1.0]], "state": [5.0, 5.0, 0.0, 1.0]})
    with pytest.raises(ValueError, match="unknown reset options"):
        vec.reset(seed=1, options={"speed": 1.0})
    # a refused reset changed nothing: the generators continue as after reset(seed=0)
    single = gym.make(ID)
    single.reset(seed=1)
    assert np.array_equal(vec.reset()[0][1], single.reset()[0]) and before.shape == (2, 17)
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1"):
        Dubins4DCirclesVectorEnv(0)
    with pytest.raises(ValueError, match="autoreset_mode must be one of"):
        Dubins4DCirclesVectorEnv(2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="render_mode must be None"):
        Dubins4DCirclesVectorEnv(2, render_mode="rgb_array")
    with pytest.raises(ValueError, match="driver_solver must be 'closed_form'"):
        Dubins4DCirclesVectorEnv(2, driver_solver="osqp")
    with pytest.raises(ValueError, match="step_dt must be"):  # the single env's validation
        Dubins4DCirclesVectorEnv(2, step_dt=-1.0)


def test_reset_options_apply_to_every_sub_env():
    vec = gym.make_vec(ID, num_envs=3, vectorization_mode="vector_entry_point")
    obs, info = vec.reset(seed=0, options={"state": [1.0, 2.0, 0.5, 1.0], "goal": [-5.0, -5.0, 1.0]})
    assert np.all(info["state"] == [1.0, 2.0, 0.5, 1.0])
    assert np.all(obs[:, 1] == np.float32(-6.0)) and np.all(obs[:, 2] == np.float32(-7.0))


def test_gymnasium_vector_wrappers_work():
    from gymnasium.wrappers.vector import NormalizeObservation, RecordEpisodeStatistics

    n = 4
    vec = gym.make_vec(ID, num_envs=n, vectorization_mode="vector_entry_point")
    env = NormalizeObservation(RecordEpisodeStatistics(vec))  # the default key, "episode", is the wrapper's
    env.reset(seed=0)
    a = {"active_ctrl": np.zeros(n, np.int64), "turnrate_ctrl": np.zeros((n, 1)), "accel_ctrl": np.zeros((n, 1))}
    lengths, steps_done, returns, env_returns = [], [], [], []
    for _ in range(300):
        _, _, te, tr, info = env.step(a)
        if "episode" in info:
            m = info["_episode"]
            lengths += info["episode"]["l"][m].tolist()
            returns += info["episode"]["r"][m].tolist()
            steps_done += info["episode_stats"]["n_env_steps"][m].tolist()
            env_returns += info["episode_stats"]["cum_reward"][m].tolist()
    assert lengths and lengths == steps_done  # the wrapper counts the steps the env reports
    assert returns == env_returns
