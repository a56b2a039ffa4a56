"""FlattenGuardianAction and GuardianReward: the RL-ready view of a parallel-autonomy env."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmm_envs  # noqa: F401
from rmm_envs.wrappers.rl import FlattenGuardianAction, GuardianReward

STRAIGHT_AT = {"state": [0.0, 0.0, 0.0, 1.0], "obstacles": [[3.0, 0.0, 1.0]], "goal": [-8.0, -8.0, 0.5]}
STRAIGHT_TO_GOAL = {"state": [0.0, 0.0, 0.0, 1.0], "obstacles": [[-6.0, 6.0, 1.0]], "goal": [1.5, 0.0, 0.5]}


def test_flat_action_maps_onto_the_bounds():
    space = gym.make("Dubins4DGuarded-v0").action_space
    to = FlattenGuardianAction.to_guardian
    assert space.parse(to(space, [1.0, -1.0, 1.0])) == (True, pytest.approx([-0.25, 0.5]))
    on, u = space.parse(to(space, [0.6, 0.0, 0.5]))
    assert on and u.tolist() == [0.0, 0.25]
    on, u = space.parse(to(space, [0.5, 1.0, 1.0]))  # 0.5 is not > 0.5: the driver keeps control
    assert not on and u.tolist() == [0.0, 0.0]
    on, u = space.parse(to(space, [1.0, 7.0, -3.0]))  # clipped to the unit box first
    assert u.tolist() == [0.25, -0.5]


@pytest.mark.parametrize(
    "action, msg",
    [
        ([1.0, 0.0], "has 3 numbers"),
        ([1.0, np.nan, 0.0], "index 1 must be finite"),
        ([np.inf, 0.0, 0.0], "index 0 must be finite"),
    ],
)
def test_flat_action_errors_name_the_problem(action, msg):
    env = FlattenGuardianAction(gym.make("Dubins4DGuarded-v0"))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=msg):
        env.step(np.asarray(action, dtype=np.float32))


def test_wrapped_env_passes_gymnasium_checks():
    env = GuardianReward(FlattenGuardianAction(gym.make("Dubins4DGuarded-v0")))
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
    check_env(env, skip_render_check=True)
    assert GuardianReward(gym.make("Dubins4DParallel-v0")).action_space == gym.make("Dubins4DParallel-v0").action_space


def _run(env, action, options):
    env.reset(seed=0, options=options)
    rewards, infos = [], []
    while True:
        _, r, term, trunc, info = env.step(action)
        rewards.append(r)
        infos.append(info)
        if term or trunc:
            return rewards, infos


def test_reward_on_collision_and_intervention_cost_per_simulated_second():
    env = GuardianReward(FlattenGuardianAction(gym.make("Dubins4DGuarded-v0")))
    rewards, infos = _run(env, np.array([1.0, 0.0, 0.0], np.float32), STRAIGHT_AT)  # hold course: crash into x = 2
    assert infos[-1]["outcome"] == "collision" and infos[-1]["env_reward"] == -1.0
    # every step is 0.1 s under guardian control: -0.005 each, and -10 at the crash
    assert rewards[:-1] == pytest.approx([-0.005] * (len(rewards) - 1))
    assert rewards[-1] == pytest.approx(-10.005)
    assert len(rewards) == 20  # the obstacle edge is 2 m ahead at 1 m/s: 20 steps of 0.1 s


def test_reward_on_goal_and_no_cost_for_the_driver():
    env = GuardianReward(gym.make("Dubins4DGuarded-v0"), goal_bonus=2.0, intervention_cost=1.0)
    inactive = env.action_space.inactive()
    rewards, infos = _run(env, inactive, STRAIGHT_TO_GOAL)
    assert infos[-1]["outcome"] == "goal" and infos[-1]["env_reward"] == 1.0
    assert rewards[-1] == 2.0 and set(rewards[:-1]) <= {0.0}


def test_non_blocking_steps_are_charged_by_their_length():
    env = GuardianReward(
        FlattenGuardianAction(gym.make("Dubins4DParallel-v0", clock="fixed:20")), intervention_cost=1.0
    )
    env.reset(seed=0, options=STRAIGHT_AT)
    _, r0, *_, info0 = env.step(np.array([1.0, 0.0, 0.0], np.float32))  # the first interval is the driver's
    assert not info0["active"] and r0 == 0.0
    _, r1, *_, info1 = env.step(np.array([1.0, 0.0, 0.0], np.float32))
    assert info1["active"] and r1 == pytest.approx(-(0.02 * 10 + 0.1))  # lap x time_accel + base_step


@pytest.mark.parametrize(
    "kw",
    [
        {"goal_bonus": -1.0},
        {"collision_penalty": math.inf},
        {"intervention_cost": float("nan")},
        {"goal_bonus": True},
        {"collision_penalty": "10"},
    ],
)
def test_reward_weights_are_checked(kw):
    with pytest.raises(ValueError, match=next(iter(kw))):
        GuardianReward(gym.make("Dubins4DGuarded-v0"), **kw)


def test_wrappers_refuse_envs_without_the_contract():
    with pytest.raises(TypeError, match="FlattenGuardianAction needs a parallel-autonomy env.*Dubins3DMaze-v0"):
        FlattenGuardianAction(gym.make("Dubins3DMaze-v0"))
    with pytest.raises(TypeError, match="GuardianReward needs a parallel-autonomy env"):
        GuardianReward(gym.make("Dubins3DMaze-v0"))
