"""The guarded-env builder (:mod:`rmm_envs.envs.any_env`) and its two registered examples."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.envs.any_env import guarded, parallel
from rmm_envs.envs.target_driver import TargetDriver
from rmm_envs.systems.cartpole.guarded import CARTPOLE_K


def push_right(obs):
    return 1


def balance(obs):  # the examples' safe default at the centre
    return TargetDriver(CARTPOLE_K, 0, 2, 0.02, 0.5, 1.0, 1.0, 1.0, 0.2, 1.0, True).balance(obs)


def never(obs):
    return False


def run(env, action_of, seed=0):
    obs, info = env.reset(seed=seed)
    steps = [(obs, info)]
    while True:
        obs, r, term, trunc, info = env.step(action_of(env, obs, info))
        steps.append((obs, info))
        if term or trunc:
            return steps, term, trunc


def inactive(env, obs, info):
    return env.action_space.inactive()


def test_failure_is_a_collision_with_cost_one_on_the_failing_step_only():
    env = guarded("CartPole-v1", driver=push_right, safe_default=0, success=never)
    steps, term, trunc = run(env, inactive)
    assert term and not trunc
    infos = [i for _, i in steps[1:]]
    assert infos[-1]["outcome"] == "collision" and infos[-1]["episode_stats"]["outcome"] == "collision"
    assert [i["cost"] for i in infos] == [0.0] * (len(infos) - 1) + [1.0]
    assert infos[-1]["episode_stats"]["cum_cost"] == 1.0
    assert "final_speed" not in infos[-1]["episode_stats"]  # optional, and there is no vehicle
    assert abs(steps[-1][0][2]) > 12 * 2 * np.pi / 360 or abs(steps[-1][0][0]) > 2.4  # CartPole's own termination


def test_success_is_a_goal_and_truncation_a_timeout():
    env = guarded("CartPole-v1", driver=balance, safe_default=0, success=lambda obs: obs[0] > -1.0)
    steps, term, trunc = run(env, inactive)
    assert term and not trunc and len(steps) == 2 and steps[-1][1]["outcome"] == "goal"
    env = guarded("CartPole-v1", driver=balance, safe_default=0, success=never, max_episode_sim_time=0.2)
    steps, term, trunc = run(env, inactive)
    assert trunc and not term and len(steps) == 11 and steps[-1][1]["outcome"] == "timeout"
    assert steps[-1][1]["episode_stats"]["cum_sim_time"] == pytest.approx(0.2)
    # the env's own truncation (CartPole-v1 stops at 500 steps) is a timeout as well
    env = guarded("CartPole-v1", driver=balance, safe_default=0, success=never, max_episode_sim_time=100.0)
    steps, term, trunc = run(env, inactive)
    assert trunc and steps[-1][1]["outcome"] == "timeout" and steps[-1][1]["episode_stats"]["n_env_steps"] == 500


def _twin(env):
    """A bare copy of the guarded env's simulator in the same state."""
    raw = gym.make(env.unwrapped.env.spec.id).unwrapped
    raw.reset(seed=0)
    raw.state = np.array(env.unwrapped.env.unwrapped.state, dtype=float)
    return raw


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_nominal_control_is_what_the_driver_applies_and_an_active_action_applies_the_guardians(seed):
    env = guarded("CartPole-v1", driver=balance, safe_default=0, success=never, max_episode_sim_time=0.5)
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(20):
        raw = _twin(env)
        nominal = info["nominal_control"]
        assert nominal.tolist() == [float(balance(obs))]  # the driver's action as the control
        if rng.random() < 0.5:
            action, applied = env.action_space.inactive(), balance(obs)
        else:
            u = rng.uniform(0.0, 2.0)
            action, applied = env.action_space.active([u]), int(np.floor(u))
        expected = raw.step(applied)[0]
        obs, _, term, trunc, info = env.step(action)
        assert np.array_equal(obs, expected)
        if term or trunc:
            break


def test_a_box_action_env_applies_the_guardians_force_bit_for_bit():
    pytest.importorskip("mujoco")
    env = gym.make("InvertedPendulumGuarded-v0")
    env.reset(seed=3)
    inner = env.unwrapped.env.unwrapped
    qpos, qvel = inner.data.qpos.copy(), inner.data.qvel.copy()
    obs = env.step(env.action_space.active([1.7]))[0]
    raw = gym.make("InvertedPendulum-v5").unwrapped
    raw.reset(seed=0)
    raw.set_state(qpos, qvel)
    assert np.array_equal(obs, raw.step(np.array([1.7], dtype=np.float32))[0])


def test_an_sb3_style_policy_drives_and_begin_episode_gets_a_seeded_generator():
    class Policy:
        def __init__(self):
            self.draws = []

        def begin_episode(self, rng):
            self.draws.append(rng.integers(1000))

        def predict(self, obs, deterministic=False):
            assert deterministic
            return np.array(balance(obs)), None

    p = Policy()
    env = guarded("CartPole-v1", driver=p, safe_default=0, success=never)
    _, info = env.reset(seed=4)
    env.reset(seed=4)
    env.reset(seed=5)
    assert p.draws[0] == p.draws[1] != p.draws[2]
    assert info["nominal_control"].shape == (1,)


def test_the_safe_default_is_the_action_spaces_and_a_constant_is_served_as_is():
    env = guarded("CartPole-v1", driver=balance, safe_default=0, success=never, controls=("push",))
    space = env.action_space
    assert isinstance(space, GuardianActionSpace) and space.controls == ("push",)
    assert space.control_low.tolist() == [0.0] and space.control_high.tolist() == [2.0]
    assert space.safe_default.policy(space, np.random.default_rng(0))(np.zeros(4)).tolist() == [0.0]
    env = guarded("CartPole-v1", driver=balance, safe_default=balance, success=never)
    pol = env.action_space.safe_default.policy(env.action_space, np.random.default_rng(0))
    assert pol(np.array([0.0, 0.0, 0.1, 0.0])).tolist() == [1.0]


def test_bad_input_is_named():
    with pytest.raises(
        ValueError, match=r"the driver .* returned the action 2, outside the env's action space Discrete\(2\)"
    ):
        guarded("CartPole-v1", driver=lambda obs: 2, safe_default=0, success=never).reset(seed=0)
    with pytest.raises(
        ValueError,
        match=r"returned the action array\(\[5.\], dtype=float32\), outside the env's action "
        r"space Box\(-3.0, 3.0, \(1,\), float32\)",
    ):
        pytest.importorskip("mujoco")
        guarded(
            "InvertedPendulum-v5",
            driver=lambda obs: np.array([5.0], np.float32),
            safe_default=np.zeros(1),
            success=never,
        ).reset(seed=0)
    with pytest.raises(
        TypeError,
        match=r"safe_default must be a callable obs -> action, an SB3-style policy or a "
        r"constant action in the env's action space Discrete\(2\), got 'stop'",
    ):
        guarded("CartPole-v1", driver=balance, safe_default="stop", success=never)
    with pytest.raises(TypeError, match=r"driver must be a callable obs -> action or an object with predict"):
        guarded("CartPole-v1", driver=3, safe_default=0, success=never)
    with pytest.raises(TypeError, match=r"success must be a callable success\(obs\) -> bool, got True"):
        guarded("CartPole-v1", driver=balance, safe_default=0, success=True)
    with pytest.raises(
        ValueError,
        match=r"Pendulum-v1 has no known failure notion .* give failure='terminated' if its "
        r"termination is a failure, or failure=callable\(obs\) -> bool",
    ):
        guarded(
            "Pendulum-v1",
            driver=lambda obs: np.zeros(1, np.float32),
            safe_default=np.zeros(1, np.float32),
            success=never,
        )
    with pytest.raises(
        TypeError, match=r"failure must be None, 'terminated' or a callable failure\(obs\) -> bool, got 'x'"
    ):
        guarded("CartPole-v1", driver=balance, safe_default=0, success=never, failure="x")
    with pytest.raises(
        ValueError,
        match=r"controls must name each control of CartPole-v1's action space Discrete\(2\) "
        r"\(1 control\), got \('force', 'angle'\)",
    ):
        guarded("CartPole-v1", driver=balance, safe_default=0, success=never, controls=("force", "angle"))
    with pytest.raises(
        ValueError,
        match=r"controls must name each control .* got 'force' \(a string; one name is "
        r"\('force',\)\)",
    ):  # not five controls 'f', 'o', 'r', 'c', 'e'
        guarded("CartPole-v1", driver=balance, safe_default=0, success=never, controls="force")


def test_a_failure_of_ones_own_ends_a_never_terminating_env():
    env = guarded(
        "Pendulum-v1",
        driver=lambda obs: np.array([2.0], np.float32),
        safe_default=np.zeros(1, np.float32),
        success=never,
        failure=lambda obs: abs(obs[2]) > 3.0,
    )
    steps, term, _ = run(env, inactive)
    assert term and steps[-1][1]["outcome"] == "collision" and abs(steps[-1][0][2]) > 3.0
    assert all(abs(o[2]) <= 3.0 for o, _ in steps[:-1])


@pytest.mark.parametrize("env_id", ["CartPoleParallel-v0", "InvertedPendulumParallel-v0"])
def test_fixed_clock_episodes_repeat_exactly(env_id):
    if env_id.startswith("Inverted"):
        pytest.importorskip("mujoco")

    def episode():
        env = gym.make(env_id, clock="fixed:1")
        steps, _, _ = run(env, inactive, seed=11)
        return [o.tolist() for o, _ in steps], steps[-1][1]["episode_stats"]

    a, b = episode(), episode()
    assert a == b
    base_step = 0.02 if env_id.startswith("Cart") else 0.04  # one env step; plus 1 ms x time_accel 10 per step
    assert a[1]["cum_sim_time"] == pytest.approx(a[1]["n_env_steps"] * (0.001 * 10 + base_step))


def test_a_short_interval_carries_over_to_the_next():
    env = parallel("CartPole-v1", driver=balance, safe_default=0, success=never, base_step=0.015, clock="fixed:0")
    obs0, _ = env.reset(seed=0)
    obs1 = env.step(env.action_space.inactive())[0]  # 0.015 s: no env step of 0.02 s ends in it
    obs2 = env.step(env.action_space.inactive())[0]  # 0.03 s: one has
    assert np.array_equal(obs0, obs1) and not np.array_equal(obs1, obs2)


def test_the_sampler_draws_non_failed_states_half_from_the_driver_and_repeats_with_its_generator():
    env = gym.make("CartPoleGuarded-v0")
    env.reset(seed=0)
    base = env.unwrapped
    a = base.sample_states(np.random.default_rng(7), 10)
    b = base.sample_states(np.random.default_rng(7), 10)
    assert a.shape == (10, 4) and np.array_equal(a, b)
    assert np.all(np.abs(a[:, 0]) <= 2.4) and np.all(np.abs(a[:, 2]) <= 12 * 2 * np.pi / 360)
    # the adapter's half is uniform on |x_dot| < 2 (1/8 of it below 0.25); the driver's half
    # is mostly its cart holding still at a target
    many = base.sample_states(np.random.default_rng(8), 400)
    assert np.all(np.abs(many[:200, 1]) < 2.0)
    assert np.mean(np.abs(many[:200, 1]) < 0.25) < 0.25 < 0.5 < np.mean(np.abs(many[200:, 1]) < 0.25)
    assert np.array_equal(base.observe_states(a), a.astype(np.float32))
    assert base.default_horizon == 0.08 and base.risk_scene().name == "CartPole-v1"


def test_rmm_bench_runs_every_applicable_guardian_and_names_cbf_and_hj_as_not_applying(tmp_path, capsys):
    from rmm_bench.run_args import parse_run
    from rmm_bench.run_plan import applicable

    config = parse_run(
        ["--env", "CartPoleParallel-v0", "--agent", "all", "--clock", "fixed:1", "--out", str(tmp_path)], "rmm-bench"
    )
    config, _ = applicable(config)
    assert config.agents == ("lrmm", "random", "inactive", "brakes")
    err = capsys.readouterr().err
    for name in ("cbf", "hj"):
        assert (
            f"--agent all: {name} does not apply to --env CartPoleParallel-v0, skipped: guardian {name!r} applies to "
            "Dubins4D envs and the maze car"
        ) in err
    assert config.env_kwargs == {"time_accel": 10.0, "base_step": 0.02, "clock": "fixed:1"}  # the env's own base step


@pytest.mark.parametrize(
    "env_id, upright, tipping",
    [
        ("CartPoleParallel-v0", [0, 0, 0, 0], [0, 0, 0.19, 1.5]),
        ("InvertedPendulumParallel-v0", [0, 0, 0, 0], [0, 0.18, 0, 1.0]),
    ],
)
def test_the_shipped_lrmm_applies_the_safe_default_when_the_pole_is_about_to_fall(env_id, upright, tipping):
    if env_id.startswith("Inverted"):
        pytest.importorskip("mujoco")
    from rmm_guardians import make_guardian

    env = gym.make(env_id, clock="fixed:1")
    env.reset(seed=0)
    g = make_guardian("lrmm", env_id=env_id)
    # the shipped model's decision: no strategies, the core alone (the env's safe default while risk > threshold)
    assert g.strategies == () and g.threshold_source == "stored decision"
    g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    space = env.action_space
    calm = g.act(np.array(upright, dtype=space_dtype(env)), {})
    assert calm == space.inactive() or (calm["active_ctrl"] == 0)
    assert g.last_risk < g.threshold
    hot = np.array(tipping, dtype=space_dtype(env))
    act = g.act(hot, {})
    assert g.last_risk > g.threshold and act["active_ctrl"] == 1
    safe = space.safe_default.policy(space, np.random.default_rng(0))(hot)
    assert np.array_equal(act["force_ctrl"], safe)


def space_dtype(env):
    return env.observation_space.dtype
