"""The envs under the wrappers their users reach for: Gymnasium's ``RecordEpisodeStatistics``
(single and vector), Stable-Baselines3's ``Monitor``, and a PPO model trained through
``FlattenGuardianAction`` and benchmarked through ``SB3Guardian`` (one flat-action mapping)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import RecordEpisodeStatistics

import rmm_envs
from rmm_envs.envs.guarded import EPISODE_KEY
from rmm_envs.wrappers import FlattenGuardianAction
from rmm_guardians import SB3Guardian

GUARDIAN_ENVS = [e for e in rmm_envs.ENV_IDS if e not in ("Dubins3DMaze-v0", "QuadrotorRoom-v0")]


def _run(env, steps: int, action):
    infos = []
    env.reset(seed=1)
    for _ in range(steps):
        _, _, term, trunc, info = env.step(action)
        if term or trunc:
            infos.append(info)
            env.reset()
    return infos


@pytest.mark.parametrize("env_id", GUARDIAN_ENVS)
def test_record_episode_statistics_and_monitor_own_the_episode_key(env_id):
    from stable_baselines3.common.monitor import Monitor

    kwargs = {"max_episode_sim_time": 3.0} if "Maze" not in env_id else {"max_episode_sim_time": 6.0}
    base = gym.make(env_id, clock="fixed:1", **kwargs)
    inactive = base.unwrapped.action_space.inactive()
    ended = _run(RecordEpisodeStatistics(base), 200, inactive)
    assert ended, "no episode ended"
    for info in ended:
        # the wrapper's own statistics, and the env's beside them, agree on the length and return
        assert info["episode"]["l"] == info[EPISODE_KEY]["n_env_steps"]
        assert info["episode"]["r"] == pytest.approx(info[EPISODE_KEY]["cum_reward"])
    ended = _run(Monitor(gym.make(env_id, clock="fixed:1", **kwargs)), 200, inactive)
    assert ended and all(i["episode"]["l"] == i[EPISODE_KEY]["n_env_steps"] for i in ended)


def test_vector_record_episode_statistics_on_the_default_key():
    from gymnasium.wrappers.vector import RecordEpisodeStatistics as VectorRecord

    n = 3
    env = VectorRecord(
        gym.make_vec(
            "Dubins4DGuarded-v0",
            num_envs=n,
            vectorization_mode="vector_entry_point",
            max_episode_sim_time=2.0,
            clock="fixed:1",
        )
    )
    env.reset(seed=0)
    zeros = {"active_ctrl": np.zeros(n, np.int64), "turnrate_ctrl": np.zeros(n), "accel_ctrl": np.zeros(n)}
    seen = 0
    for _ in range(60):
        *_, info = env.step(zeros)
        if "episode" in info:
            m = info["_episode"]
            assert info["episode"]["l"][m].tolist() == info[EPISODE_KEY]["n_env_steps"][m].tolist()
            seen += int(m.sum())
    assert seen >= n


def test_the_flat_action_of_the_issue_maps_alike_through_the_wrapper_and_the_adapter():
    """``[0.9, 0.1, 0.3]``: turn 0.025 and acceleration 0.15 both ways (the midpoint of each
    bound plus 0.1 and 0.3 of its half-width), not 0.1 and 0.3 through one of them."""
    env = FlattenGuardianAction(gym.make("Dubins4DGuarded-v0"))
    space = env.unwrapped.action_space
    through_wrapper = env.action(np.array([0.9, 0.1, 0.3], np.float32))  # what SB3 hands the wrapper

    class Fixed:
        def predict(self, obs, deterministic=True):
            return np.array([0.9, 0.1, 0.3], np.float32), None

    g = SB3Guardian(Fixed())
    g.reset(seed=0, observation_space=env.observation_space, action_space=space)
    through_adapter = g.act(np.zeros(17, np.float32), {})
    u = space.parse(through_wrapper)[1]
    assert u.tolist() == pytest.approx([0.025, 0.15], abs=1e-7)
    assert space.parse(through_adapter)[1].tolist() == u.tolist()
    assert space.to_unit(u) == pytest.approx(np.float32([0.1, 0.3]))


def test_a_saved_ppo_model_applies_the_same_controls_through_sb3guardian(tmp_path, monkeypatch):
    """Train PPO (briefly) through the wrapper, save, load: on the observations of an episode
    the loaded model through ``SB3Guardian`` gives the very actions the wrapper made of the
    trained model's outputs."""
    import tempfile

    import torch
    from stable_baselines3 import PPO

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # stable-baselines3's logger folder, not in /tmp

    torch.set_num_threads(1)
    train_env = FlattenGuardianAction(gym.make("Dubins4DGuarded-v0"))
    model = PPO("MlpPolicy", train_env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu", verbose=0)
    model.learn(total_timesteps=64)
    model.save(tmp_path / "ppo.zip")
    loaded = PPO.load(tmp_path / "ppo.zip", device="cpu")

    env = gym.make("Dubins4DGuarded-v0", clock="fixed:1")
    space = env.unwrapped.action_space
    guardian = SB3Guardian(loaded, deterministic=False)
    guardian.reset(seed=0, observation_space=env.observation_space, action_space=space)
    obs, info = env.reset(seed=2)
    active = 0
    for k in range(60):
        torch.manual_seed(k)
        flat, _ = model.predict(obs, deterministic=False)  # the trained model, sampling
        expected = train_env.action(flat)
        torch.manual_seed(k)
        got = guardian.act(obs, info)  # the saved and loaded model, the same draw
        assert got["active_ctrl"] == expected["active_ctrl"]
        assert space.parse(got)[1].tolist() == space.parse(expected)[1].tolist()
        active += got["active_ctrl"]
        obs, _, term, trunc, info = env.step(got)
        if term or trunc:
            obs, info = env.reset(seed=3 + k)
    assert 0 < active < 60  # both branches of the flag were met
