import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.clocks import CPUClock, FixedLatencyClock, ManualClock, WallClock, make_clock
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv
from rmm_envs.wrappers import NonBlockingStepping

OPTS = {"state": [0, 0, 0, 1.0], "goal": [9, 9, 0.5], "obstacles": [[-9, -9, 1.0]]}


def act(u1, u2, active=1):
    return {
        "active_ctrl": active,
        "turnrate_ctrl": np.array([u1], np.float32),
        "accel_ctrl": np.array([u2], np.float32),
    }


def test_lap_is_elapsed_times_accel_plus_base():
    clock = ManualClock()
    env = NonBlockingStepping(Dubins4DGuardedEnv(), time_accel=10.0, base_step=0.1, clock=clock)
    env.reset(options=OPTS)
    clock.advance(0.05)
    _, _, _, _, info = env.step(act(0, -0.5))
    assert info["sim_time"] == pytest.approx(0.6)
    clock.advance(0.0)
    _, _, _, _, info = env.step(act(0, -0.5))
    assert info["sim_time"] == pytest.approx(0.7)


def test_action_applies_one_step_late():
    clock = ManualClock()
    env = NonBlockingStepping(Dubins4DGuardedEnv(), clock=clock)
    env.reset(options=OPTS)
    _, _, _, _, info = env.step(act(0.2, -0.5))
    assert info["active"] is False  # the first lap belongs to the driver
    _, _, _, _, info = env.step(act(0, 0, active=0))
    assert info["active"] is True
    np.testing.assert_allclose(info["control"], [0.2, -0.5], atol=1e-7)
    _, _, _, _, info = env.step(act(0, 0))
    assert info["active"] is False


def test_thinking_time_is_charged_to_the_world_and_the_stats():
    clock = ManualClock()
    env = NonBlockingStepping(Dubins4DGuardedEnv(max_episode_sim_time=5.0), clock=clock)
    env.reset(options=OPTS)
    done = False
    n = 0
    while not done:
        clock.advance(0.04)
        _, _, te, tr, info = env.step(act(0, 0, active=0))
        n += 1
        done = te or tr
    ep = info["episode_stats"]
    assert ep["n_env_steps"] == n == 10  # 0.5 s per step
    assert ep["cum_compute_time"] == pytest.approx(0.4)
    assert ep["cum_sim_time"] == pytest.approx(5.0)


def test_fixed_clock_episodes_are_reproducible():
    def run():
        env = gym.make("Dubins4DParallel-v0", clock="fixed:3")
        obs, _ = env.reset(seed=5)
        out = [obs]
        while True:
            obs, r, te, tr, info = env.step(act(0, 0, active=0))
            out.append(obs)
            if te or tr:
                return np.array(out), info

    a, ia = run()
    b, ib = run()
    np.testing.assert_array_equal(a, b)
    assert ia["episode_stats"] == ib["episode_stats"]
    np.testing.assert_allclose(np.diff(a[:, 0].astype(float)), 0.003 * 10 + 0.1, atol=1e-5)


def test_bad_action_does_not_advance_the_world():
    clock = ManualClock()
    env = NonBlockingStepping(Dubins4DGuardedEnv(), clock=clock)
    env.reset(options=OPTS)
    with pytest.raises(ValueError, match="accel_ctrl"):
        env.step(act(0, np.nan))
    assert env.unwrapped.sim_time == 0.0


@pytest.mark.parametrize("kwargs, match", [({"time_accel": 0.5}, "time_accel"), ({"base_step": 0}, "base_step")])
def test_bad_wrapper_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        NonBlockingStepping(Dubins4DGuardedEnv(), **kwargs)


def test_wrapper_needs_a_simulate_method():
    with pytest.raises(TypeError, match="simulate"):
        NonBlockingStepping(gym.make("CartPole-v1"))


def test_clock_factory():
    assert isinstance(make_clock(None), WallClock)
    assert isinstance(make_clock("cpu"), CPUClock)
    c = make_clock("fixed:20")
    assert isinstance(c, FixedLatencyClock) and c.elapsed() == pytest.approx(0.02)
    for bad in ("fixed:abc", "sundial"):
        with pytest.raises(ValueError, match="clock"):
            make_clock(bad)
    with pytest.raises(ValueError, match="latency"):
        FixedLatencyClock(-1)
    with pytest.raises(ValueError, match="backwards"):
        ManualClock().advance(-1)


class RecordingClock(ManualClock):
    """A manual clock that records every start() and elapsed() with the time it happened."""

    def __init__(self):
        self.events = []
        super().__init__()

    def start(self):
        super().start()
        self.events.append(("start", self.t))

    def elapsed(self):
        lap = super().elapsed()
        self.events.append(("elapsed", self.t, lap))
        return lap


class SlowPhysicsEnv(Dubins4DGuardedEnv):
    """The env's own work takes (clock) time: 0.3 s before the physics and 0.7 s after it."""

    def simulate(self, duration, active, control, compute_time=0.0):
        self.clock_under_test.advance(0.3)
        out = super().simulate(duration, active, control, compute_time)
        self.clock_under_test.advance(0.7)
        return out


@pytest.mark.parametrize("wrapped", [True, False])
def test_only_the_agents_time_between_steps_is_charged_never_the_envs_own_work(wrapped):
    clock = RecordingClock()
    inner = SlowPhysicsEnv(max_episode_sim_time=50.0, clock=clock)
    inner.clock_under_test = clock
    env = NonBlockingStepping(inner, time_accel=10.0, base_step=0.1, clock=clock) if wrapped else inner
    env.reset(options=OPTS)
    thinking = [0.01, 0.02, 0.0, 0.04, 0.03]
    sim_before = 0.0
    for dt in thinking:
        clock.advance(dt)  # the agent thinks
        _, _, te, tr, info = env.step(act(0, 0, active=0))
        assert not (te or tr)
        if wrapped:  # the world advanced by the agent's time only
            assert info["sim_time"] - sim_before == pytest.approx(dt * 10.0 + 0.1, abs=1e-12)
        sim_before = info["sim_time"]
    laps = [e[2] for e in clock.events if e[0] == "elapsed"]
    assert laps == pytest.approx(thinking, abs=1e-12)  # each lap is exactly the agent's thinking
    assert inner.episode_statistics()["cum_compute_time"] == pytest.approx(sum(thinking), abs=1e-12)
    # every lap starts when step returns: the last start() of a step comes after the env's work
    starts = [e[1] for e in clock.events if e[0] == "start"]
    assert starts[-1] == pytest.approx(clock.t)
