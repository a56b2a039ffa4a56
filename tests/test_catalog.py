"""The env naming scheme (rmm_envs.catalog): old ids are aliases that warn and build the new env."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs
from rmm_envs.catalog import RENAMED, canonical_id, stored_id


def test_renamed_ids_follow_the_scheme_and_are_not_current_ids():
    assert RENAMED == {"Dubins4DCircles-v0": "Dubins4DCirclesGuarded-v0", "Dubins4DParallel-v0": "Dubins4DCirclesParallel-v0",
                       "Dubins4DMap-v0": "Dubins4DMapGuarded-v0"}
    for old, new in RENAMED.items():
        assert old in gym.registry and new in rmm_envs.ENV_IDS and old not in rmm_envs.ENV_IDS
        assert canonical_id(old) == canonical_id(new) == new
        assert stored_id(old) == stored_id(new) == old
    assert canonical_id("QuadrotorRoom-v0") == stored_id("QuadrotorRoom-v0") == "QuadrotorRoom-v0"


@pytest.mark.parametrize("old", ["Dubins4DCircles-v0", "Dubins4DParallel-v0"])
def test_an_old_id_warns_at_the_callers_line_and_builds_the_same_env(old):
    new = RENAMED[old]
    kwargs = {"clock": "fixed:1"} if "Parallel" in new else {}
    with pytest.warns(DeprecationWarning, match=f"'{old}' was renamed '{new}'") as record:
        env_old = gym.make(old, **kwargs)
    assert record[0].filename == __file__  # shown by Python's default filter when a script makes it
    env_new = gym.make(new, **kwargs)
    assert type(env_old.unwrapped) is type(env_new.unwrapped)
    obs_old, _ = env_old.reset(seed=3)
    obs_new, _ = env_new.reset(seed=3)
    action = env_new.action_space.sample()
    np.testing.assert_array_equal(obs_old, obs_new)
    np.testing.assert_array_equal(env_old.step(action)[0], env_new.step(action)[0])


def test_the_new_ids_do_not_warn_and_the_vector_entry_point_moved_with_the_blocking_id():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make_vec("Dubins4DCirclesGuarded-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert type(env).__name__ == "Dubins4DCirclesVectorEnv"
    with pytest.warns(DeprecationWarning, match="'Dubins4DCircles-v0' was renamed"):
        old = gym.make_vec("Dubins4DCircles-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert type(old) is type(env)


def test_an_alias_accepts_what_its_new_id_accepts():
    from benchmarks.bench.checks import env_arguments

    assert env_arguments("Dubins4DParallel-v0") == env_arguments("Dubins4DCirclesParallel-v0") >= {"time_accel", "clock"}


def test_a_dataset_made_under_an_old_id_is_the_same_dataset_under_the_new_one():
    from rmm_envs.risk.dataset import identity

    assert identity({"env_id": "Dubins4DCircles-v0", "seed": 1}) == identity({"env_id": "Dubins4DCirclesGuarded-v0", "seed": 1})
    assert identity({"env_id": "Dubins3DMaze-v0"}) != identity({"env_id": "Dubins3DMazeGuarded-v0"})
