import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.wrappers import RiskLabel

INACTIVE = {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}


def test_adds_risk_at_reset_and_every_step():
    env = RiskLabel(gym.make("Dubins4DGuarded-v0"), branches=8, depth=2, seed=0)
    obs, info = env.reset(seed=0)
    assert 0.0 <= info["risk"] <= 1.0 and info["risk_min_ctrl"].shape == (2,)
    for _ in range(5):
        obs, r, te, tr, info = env.step(INACTIVE)
        assert 0.0 <= info["risk"] <= 1.0
        if te or tr:
            break


def test_risk_is_one_just_before_a_crash_and_zero_in_the_open():
    env = RiskLabel(gym.make("Dubins4DGuarded-v0"), seed=0)
    _, info = env.reset(options={"state": [0, 0, 0, 2.0], "goal": [-9, 9, 0.5], "obstacles": [[1.5, 0, 1.0]]})
    assert info["risk"] == 1.0
    _, info = env.reset(options={"state": [0, 0, 0, 1.0], "goal": [-9, 9, 0.5], "obstacles": [[60, 0, 1.0]]})
    assert info["risk"] == 0.0


def test_works_on_the_parallel_env_and_is_seeded():
    def risks():
        env = RiskLabel(gym.make("Dubins4DParallel-v0", clock="fixed:1"), branches=8, seed=3)
        _, info = env.reset(seed=1)
        out = [info["risk"]]
        for _ in range(3):
            out.append(env.step(INACTIVE)[4]["risk"])
        return out

    assert risks() == risks()


def test_needs_a_labelled_env_and_names_it_and_the_missing_hooks():
    with pytest.raises(
        TypeError,
        match=r"^MountainCar-v0 \(MountainCarEnv\) is not a LabelledEnv.*risk_scene is missing; "
        r"true_state is missing; no risk adapter serves it either \(adapters exist "
        r"for CartPole-v1, Pendulum-v1 \(with failure=\), InvertedPendulum-v5, "
        r".*SnapshotSimulator",
    ):
        RiskLabel(gym.make("MountainCar-v0"))


@pytest.mark.parametrize(
    "kwargs, match",
    [({"branches": 0}, "branches"), ({"metric": "cvar", "alpha": 2.0}, "alpha"), ({"metric": "nope"}, "metric")],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RiskLabel(gym.make("Dubins4DGuarded-v0"), **kwargs)
