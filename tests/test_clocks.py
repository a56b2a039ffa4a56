"""The clocks' documented defaults and refusals, and the non-blocking wrapper's argument checks."""

import re
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.clocks import FixedLatencyClock, ManualClock, WallClock, make_clock
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv
from rmm_envs.wrappers import NonBlockingStepping


def test_clock_specs_by_name():
    assert type(make_clock("wall")) is WallClock and type(make_clock(" Wall ")) is WallClock
    zero = make_clock("fixed:0")
    assert isinstance(zero, FixedLatencyClock) and zero.elapsed() == 0.0
    assert make_clock("fixed:2.5").elapsed() == 0.0025 and make_clock(" FIXED:2 ").elapsed() == 0.002
    # mistyped forms are refused, naming the value and the accepted forms (none runs as 0 ms)
    for bad in (
        "fixed",
        "fixed2",
        "fixed=2",
        "fixed:",
        "fixed:2:3",
        "fixed:-1",
        "fixed:nan",
        "fixed:inf",
        "fixed:2ms",
        "wal",
        "cpu:1",
        "",
    ):
        with pytest.raises(
            ValueError,
            match=rf"unknown clock {re.escape(repr(bad))}; expected 'wall', 'cpu' or "
            r"'fixed:MS' \(MS a number of milliseconds >= 0, e\.g\. 'fixed:2'\)",
        ):
            make_clock(bad)
    with pytest.raises(ValueError, match=r"unknown clock 'fixed2'"):
        gym.make("Dubins4DGuarded-v0", clock="fixed2")
    with pytest.raises(TypeError, match="clock must be a Clock or a string, got int"):
        make_clock(5)


def test_a_clock_measures_from_its_creation_until_started():
    c = ManualClock(t=5.0)
    assert c.now() == 5.0
    c.advance(2.0)
    assert c.elapsed() == 2.0  # never started: from construction
    c.start()
    assert c.elapsed() == 0.0
    assert ManualClock().now() == 0.0  # the documented default reading
    w = WallClock()
    assert 0.0 <= w.elapsed() < 60.0
    assert repr(w) == "WallClock()" and repr(ManualClock()) == "ManualClock()"


def test_fixed_latency_bounds():
    assert FixedLatencyClock().elapsed() == 0.0  # default: no latency
    assert FixedLatencyClock(0.0).elapsed() == 0.0
    for bad in (-1e-9, float("inf"), float("nan")):
        with pytest.raises(ValueError, match="latency must be a finite number of seconds >= 0"):
            FixedLatencyClock(bad)


class NoGuardianSpace(Dubins4DGuardedEnv):
    def __init__(self):
        super().__init__()
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,))


def test_wrapper_accepts_the_papers_range_and_names_what_it_refuses():
    env = Dubins4DGuardedEnv()
    for accel in (1.0, 1.5):  # >= 1 as in the paper
        w = NonBlockingStepping(env, time_accel=accel, clock="fixed:0")
        w.reset(options={"state": [0, 0, 0, 1.0], "goal": [9, 9, 0.5], "obstacles": [[-9, -9, 1.0]]})
        _, _, _, _, info = w.step(w.unwrapped.action_space.inactive())
        assert info["sim_time"] == pytest.approx(0.1)
    with pytest.raises(
        TypeError,
        match="CartPoleEnv has no simulate.*NonBlockingStepping needs an env that can advance by an arbitrary duration",
    ):
        NonBlockingStepping(gym.make("CartPole-v1"))
    with pytest.raises(TypeError, match=r"NoGuardianSpace\.action_space must be a GuardianActionSpace.*got Box"):
        NonBlockingStepping(NoGuardianSpace())


@pytest.mark.parametrize("bad", ["fixed2", "fixed=2", "fixed"])
def test_rmm_bench_refuses_a_mistyped_clock_with_exit_2(bad, tmp_path):
    exe = Path(sys.executable).parent / "rmm-bench"
    res = subprocess.run(
        [str(exe), "--agent", "inactive", "--episodes", "1", "--clock", bad, "--out", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 2
    assert f"--clock {bad}: unknown clock {bad!r}; expected 'wall', 'cpu' or 'fixed:MS'" in res.stderr
    assert not (tmp_path / "results.db").exists()  # refused before anything ran
