"""Time accounting adds up: the guarded env's intervention time (``rmm_envs/envs/guarded.py``, Table I's
"in control" column) and ``GuardianReward``'s intervention cost (``rmm_envs/wrappers/rl.py``).

For any sequence of guardian actions, over several episodes of one env object, blocking and
non-blocking: the episode statistics' ``active_ctrl_sim_time`` is the sum of the simulated
lengths of the intervals the guardian held control (read off ``info["sim_time"]`` and
``info["active"]`` step by step), ``cum_sim_time`` the sum of all intervals, and the shaped reward
with only an intervention cost of 1 per second is exactly minus that time."""

from __future__ import annotations

import math
import re

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.envs.guarded import EPISODE_KEY
from rmm_envs.wrappers.rl import GuardianReward

ENVS = {  # short episodes: every run below ends a few of them, by timeout or earlier
    "Dubins4DGuarded-v0": dict(max_episode_sim_time=2.0),
    "Dubins4DParallel-v0": dict(max_episode_sim_time=2.0, clock="fixed:7"),  # intervals 0.007 x 10 + 0.1 s
    "Dubins3DMazeGuarded-v0": dict(max_episode_sim_time=3.0, clock="fixed:1"),
    "Dubins3DMazeParallel-v0": dict(max_episode_sim_time=3.0, clock="fixed:3"),
}
_made: dict = {}


def _env(env_id: str):
    """One wrapped env per id for the whole module (hypothesis reuses it across examples)."""
    if env_id not in _made:
        _made[env_id] = GuardianReward(
            gym.make(env_id, **ENVS[env_id]), goal_bonus=0.0, collision_penalty=0.0, intervention_cost=1.0
        )
    return _made[env_id]


def _action(space, on: bool, rng: np.random.Generator):
    if not on:
        return space.inactive()
    return space.active(rng.uniform(space.control_low, space.control_high))


def _episodes(env, bits: list[bool], seed: int, n_episodes: int) -> list[dict]:
    """Run ``n_episodes`` episodes, the guardian taking control by ``bits`` (cycled); per episode the
    sums read step by step and the env's own statistics."""
    rng = np.random.default_rng(seed)
    space = env.action_space
    out = []
    for e in range(n_episodes):
        _, info = env.reset(seed=seed + e)
        last, active_time, total, reward, active_steps, steps = float(info.get("sim_time", 0.0)), 0.0, 0.0, 0.0, 0, 0
        while True:
            _, r, term, trunc, info = env.step(_action(space, bits[steps % len(bits)], rng))
            dt, last = info["sim_time"] - last, info["sim_time"]
            assert dt > 0
            total += dt
            active_time += dt if info["active"] else 0.0
            active_steps += bool(info["active"])
            reward += r
            steps += 1
            if term or trunc:
                break
        assert "episode" not in info  # Gymnasium's RecordEpisodeStatistics owns that key
        out.append(
            dict(
                active_time=active_time,
                total=total,
                reward=reward,
                steps=steps,
                active_steps=active_steps,
                stats=info[EPISODE_KEY],
            )
        )
    return out


@pytest.mark.parametrize("env_id", list(ENVS))
@settings(max_examples=4, deadline=None)
@given(bits=st.lists(st.booleans(), min_size=1, max_size=8), seed=st.integers(0, 1000))
def test_intervention_time_and_reward_add_up_to_the_simulated_time(env_id, bits, seed):
    for ep in _episodes(_env(env_id), bits, seed, 2):
        s = ep["stats"]
        assert s["n_env_steps"] == ep["steps"] and s["n_active_ctrl_env_steps"] == ep["active_steps"]
        assert s["cum_sim_time"] == pytest.approx(ep["total"], abs=1e-9)
        assert s["active_ctrl_sim_time"] == pytest.approx(ep["active_time"], abs=1e-9)
        assert ep["reward"] == pytest.approx(-ep["active_time"], abs=1e-9)
        assert 0.0 <= s["active_ctrl_sim_time"] <= s["cum_sim_time"]


def test_hand_counted_non_blocking_intervals():
    """``Dubins4DParallel-v0`` at a fixed 7 ms lap: every interval is 0.007 x 10 + 0.1 = 0.17 s, and an
    action takes effect one interval late (the first interval is the driver's).  Guardian on at
    steps 1 and 2 only (actions given at steps 0 and 1): 2 of 3 intervals, 0.34 of 0.51 s, each
    charged 0.5 x 0.17 = 0.085."""
    env = GuardianReward(
        gym.make("Dubins4DParallel-v0", clock="fixed:7", max_episode_sim_time=0.51),
        goal_bonus=0.0,
        collision_penalty=0.0,
        intervention_cost=0.5,
    )
    env.reset(
        seed=1, options={"state": [0.0, 0.0, 0.0, 0.0], "obstacles": [[30.0, 30.0, 1.0]], "goal": [-30.0, 30.0, 0.5]}
    )
    space = env.action_space
    steps = [env.step(a) for a in (space.active([0.0, 0.0]), space.active([0.0, 0.0]), space.inactive())]
    assert [s[4]["active"] for s in steps] == [False, True, True]
    assert [s[4]["sim_time"] for s in steps] == pytest.approx([0.17, 0.34, 0.51], abs=1e-12)
    assert [s[1] for s in steps] == pytest.approx([0.0, -0.085, -0.085], abs=1e-12)
    assert steps[-1][3] and steps[-1][4][EPISODE_KEY]["active_ctrl_sim_time"] == pytest.approx(0.34, abs=1e-12)
    assert steps[-1][4][EPISODE_KEY]["cum_sim_time"] == pytest.approx(0.51, abs=1e-12)
    assert steps[-1][4][EPISODE_KEY]["n_active_ctrl_env_steps"] == 2


# ------------------------------------------------------------------ the guarded env's interval bookkeeping
@pytest.mark.parametrize("env_id", ["Dubins4DGuarded-v0", "Dubins3DMazeGuarded-v0"])
def test_intervals_are_checked_counted_and_ended_by_hand(env_id):
    """``simulate`` refuses a bad duration by value before anything is counted, counts a
    zero-length interval as a step of no time, charges the given compute time, and ends the
    episode (truncated, ``"timeout"``) when the simulated time reaches the limit within 1e-9."""
    env = gym.make(env_id, max_episode_sim_time=0.5, clock="fixed:4").unwrapped
    with pytest.raises(RuntimeError, match=r"reset\(\)"):
        env.simulate(0.1, False, None)
    env.reset(seed=2)
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ValueError, match=rf"^duration must be a finite number >= 0, got {bad}$"):
            env.simulate(bad, False, None)
    zero = env.action_space.parse(env.action_space.active(np.zeros(env.action_space.control_dim)))[1]
    _, r, term, trunc, info = env.simulate(0.0, True, zero, 0.25)
    assert (r, term, trunc) == (0.0, False, False) and info["sim_time"] == 0.0 and EPISODE_KEY not in info
    _, _, term, trunc, info = env.simulate(0.2, False, None, 0.5)
    assert not (term or trunc) and info["sim_time"] == pytest.approx(0.2)
    _, _, term, trunc, info = env.simulate(0.3 - 5e-10, True, zero, 0.75)  # 0.5 less half the tolerance: the end
    assert not term and trunc and info["outcome"] == "timeout"
    assert "episode" not in info  # Gymnasium's RecordEpisodeStatistics owns that key
    ep = info[EPISODE_KEY]
    assert ep["outcome"] == "timeout" and ep["n_env_steps"] == 3 and ep["n_active_ctrl_env_steps"] == 2
    assert ep["active_ctrl_sim_time"] == pytest.approx(0.3 - 5e-10, abs=1e-15)
    assert ep["cum_sim_time"] == pytest.approx(0.5 - 5e-10, abs=1e-15)
    assert ep["cum_compute_time"] == pytest.approx(1.5) and ep["avg_compute_time"] == pytest.approx(0.5)
    assert ep["cum_reward"] == 0.0 and ep["final_speed"] == env.final_speed()
    with pytest.raises(RuntimeError):
        env.simulate(0.1, False, None)  # the episode has ended
    env.reset(seed=2)
    _, _, term, trunc, info = env.simulate(0.5 - 2e-9, False, None)  # short of the limit by more than 1e-9
    assert not (term or trunc)


def test_a_step_charges_the_clock_and_steps_by_step_dt():
    """``step`` charges the clock's lap (4 ms) to the step and advances by ``step_dt``."""
    env = gym.make("Dubins4DGuarded-v0", clock="fixed:4", step_dt=0.25, max_episode_sim_time=0.5)
    env.reset(
        seed=0, options={"state": [0.0, 0.0, 0.0, 0.0], "obstacles": [[30.0, 30.0, 1.0]], "goal": [-30.0, 30.0, 0.5]}
    )
    env.step(env.action_space.inactive())
    _, _, _, trunc, info = env.step(env.action_space.inactive())
    assert trunc and info["sim_time"] == 0.5
    ep = info[EPISODE_KEY]
    assert (
        ep["n_env_steps"] == 2
        and ep["cum_compute_time"] == pytest.approx(0.008)
        and ep["avg_compute_time"] == pytest.approx(0.004)
    )
    assert ep["active_ctrl_sim_time"] == 0.0 and ep["n_active_ctrl_env_steps"] == 0


# ------------------------------------------------------------------ GuardianReward's arguments and record
@pytest.mark.parametrize("name", ["goal_bonus", "collision_penalty", "intervention_cost"])
@pytest.mark.parametrize("bad", [-1, -1e-300, math.nan, math.inf, True, "1", None])
def test_reward_weights_are_refused_by_name_and_value(name, bad):
    with pytest.raises(ValueError, match=rf"^{name} must be a finite number >= 0, got {re.escape(repr(bad))}$"):
        GuardianReward(gym.make("Dubins4DGuarded-v0"), **{name: bad})


def test_reward_weights_are_kept_as_floats_and_recorded_in_the_spec():
    env = GuardianReward(
        gym.make("Dubins4DGuarded-v0"), goal_bonus=np.float32(2), collision_penalty=np.int64(0), intervention_cost=3
    )
    assert (env.goal_bonus, env.collision_penalty, env.intervention_cost) == (2.0, 0.0, 3.0)
    assert all(type(v) is float for v in (env.goal_bonus, env.collision_penalty, env.intervention_cost))
    spec = env.spec.additional_wrappers[-1]
    assert spec.name == "GuardianReward" and spec.kwargs == {
        "goal_bonus": np.float32(2),
        "collision_penalty": 0,
        "intervention_cost": 3,
    }
    default = GuardianReward(gym.make("Dubins4DGuarded-v0"))
    assert (default.goal_bonus, default.collision_penalty, default.intervention_cost) == (1.0, 10.0, 0.05)


def test_reward_refuses_an_env_without_the_contract_naming_it_and_its_space():
    with pytest.raises(TypeError) as e:
        GuardianReward(gym.make("Dubins3DMaze-v0"))
    assert str(e.value) == (
        "GuardianReward needs a parallel-autonomy env (action space rmm_envs.autonomy.GuardianActionSpace); "
        "Dubins3DMaze-v0 has Box(-0.2, 0.2, (1,), float32)"
    )


def test_reward_keeps_the_env_reward_and_every_info_entry():
    """The shaped reward replaces the env's; the env's goes to ``info["env_reward"]`` and nothing
    else of the step changes (a collision: -1 from the env, -10 - 0.05 x 0.1 shaped)."""
    opts = {"state": [0.0, 0.0, 0.0, 1.0], "obstacles": [[0.15, 0.0, 0.1]], "goal": [-8.0, -8.0, 0.5]}
    plain, wrapped = gym.make("Dubins4DGuarded-v0"), GuardianReward(gym.make("Dubins4DGuarded-v0"))
    o1, i1 = plain.reset(seed=0, options=opts)
    o2, i2 = wrapped.reset(seed=0, options=opts)
    assert np.array_equal(o1, o2) and i1.keys() == i2.keys()
    a = plain.action_space.active([0.0, 0.0])
    obs1, r1, t1, tr1, info1 = plain.step(a)
    obs2, r2, t2, tr2, info2 = wrapped.step(a)
    assert np.array_equal(obs1, obs2) and (t1, tr1) == (t2, tr2) == (True, False)
    assert r1 == -1.0 and info2["env_reward"] == -1.0 and info1["outcome"] == info2["outcome"] == "collision"
    assert r2 == pytest.approx(-10.0 - 0.05 * 0.1, abs=1e-15) and type(r2) is float
    assert {k: v for k, v in info2.items() if k != "env_reward"}.keys() == info1.keys()


class _ShiftedClock(gym.Wrapper):
    """Reports the env's simulated time ``shift`` seconds late, and (``drop_at_reset``) none at reset:
    what an env with its own time origin, or an older one, gives."""

    def __init__(self, env, shift=0.0, drop_at_reset=False):
        super().__init__(env)
        self.shift, self.drop = shift, drop_at_reset

    def reset(self, **kw):
        obs, info = self.env.reset(**kw)
        info = dict(info)
        if self.drop:
            info.pop("sim_time", None)
        else:
            info["sim_time"] = info.get("sim_time", 0.0) + self.shift
        return obs, info

    def step(self, action):
        obs, r, te, tr, info = self.env.step(action)
        return obs, r, te, tr, {**info, "sim_time": info["sim_time"] + self.shift}


@pytest.mark.parametrize("shift, drop", [(5.0, False), (0.0, True)])
def test_the_cost_is_charged_from_the_time_reset_reports(shift, drop):
    """The first step's length is measured from the simulated time ``reset`` reported (0 when it
    reports none): 0.1 s here, whatever the time origin."""
    env = GuardianReward(_ShiftedClock(gym.make("Dubins4DGuarded-v0"), shift, drop), intervention_cost=1.0)
    env.reset(seed=0, options=STRAIGHT_ON)
    _, r, *_ = env.step(env.action_space.active([0.0, 0.0]))
    assert r == pytest.approx(-0.1, abs=1e-12)


STRAIGHT_ON = {"state": [0.0, 0.0, 0.0, 1.0], "obstacles": [[-6.0, 6.0, 1.0]], "goal": [1.45, 0.0, 0.5]}


def test_reaching_the_goal_under_guardian_control_pays_the_bonus_less_the_cost():
    """Holding course at 1 m/s to a goal whose edge is 0.95 m ahead: 10 steps of 0.1 s under guardian
    control, each charged 0.1 s x 1; the last also earns the bonus 2."""
    env = GuardianReward(gym.make("Dubins4DGuarded-v0"), goal_bonus=2.0, intervention_cost=1.0)
    env.reset(seed=0, options=STRAIGHT_ON)
    rewards = []
    while True:
        _, r, te, tr, info = env.step(env.action_space.active([0.0, 0.0]))
        rewards.append(r)
        if te or tr:
            break
    assert info["outcome"] == "goal" and len(rewards) == 10
    assert rewards[:-1] == pytest.approx([-0.1] * 9, abs=1e-12) and rewards[-1] == pytest.approx(2.0 - 0.1, abs=1e-12)


def test_an_env_made_without_gym_make_is_named_by_its_class():
    from rmm_envs.systems.maze.env import Dubins3DMazeEnv

    with pytest.raises(TypeError) as e:
        GuardianReward(Dubins3DMazeEnv())
    assert str(e.value).endswith("; Dubins3DMazeEnv has Box(-0.2, 0.2, (1,), float32)")


def test_a_flat_action_maps_to_the_guardian_action_exactly():
    """``to_guardian`` itself (not the env's parsing after it): components beyond [-1, 1] are clipped
    to the bounds, any shape of 1 + c numbers (and numbers as strings) is read, a wrong count is
    refused naming the controls."""
    from rmm_envs.wrappers.rl import FlattenGuardianAction

    space = gym.make("Dubins4DGuarded-v0").action_space
    to = FlattenGuardianAction.to_guardian
    for flat, controls in (
        ([1.0, 7.0, -3.0], [0.25, -0.5]),
        ([1.0, -1.5, 1.5], [-0.25, 0.5]),
        ([[0.9], [0.0], [0.5]], [0.0, 0.25]),
        (np.array([["1", "-1", "1"]]), [-0.25, 0.5]),
    ):
        a = to(space, flat)
        assert a["active_ctrl"] == 1
        assert float(a["turnrate_ctrl"][0]) == np.float32(controls[0]) and float(a["accel_ctrl"][0]) == np.float32(
            controls[1]
        )
    with pytest.raises(ValueError) as e:
        to(space, [1.0, 0.0])
    assert str(e.value) == "a flat guardian action has 3 numbers [active, turnrate_ctrl, accel_ctrl], got shape (2,)"


@pytest.mark.parametrize("env_id", ["Dubins4DGuarded-v0", "Dubins3DMazeGuarded-v0"])
def test_the_time_limit_is_reached_at_exactly_its_tolerance_and_statistics_before_a_step(env_id):
    """One interval of ``max_episode_sim_time - 1e-9`` ends the episode (the limit holds with that
    tolerance, inclusive); before any step the statistics are all zero (no division by 0 steps)."""
    env = gym.make(env_id, max_episode_sim_time=0.5, clock="fixed:4").unwrapped
    env.reset(seed=3)
    s = env.episode_statistics()
    assert (s["n_env_steps"], s["cum_sim_time"], s["avg_compute_time"], s["cum_reward"], s["outcome"]) == (
        0,
        0.0,
        0.0,
        0.0,
        None,
    )
    _, _, term, trunc, info = env.simulate(0.5 - 1e-9, False, None)
    assert trunc and not term and info["outcome"] == "timeout"
