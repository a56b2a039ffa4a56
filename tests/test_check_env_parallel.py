"""Gymnasium's ``check_env`` on the non-blocking ``...Parallel-v0`` envs (docs/getting-started.md).

Under the default wall clock, ``step`` advances the world by the measured time since the previous
``step`` or ``reset`` returned (times ``time_accel``, plus ``base_step``), so two identical calls
advance it by different amounts: ``check_step_determinism`` fails, by design, and every other check
passes.  Under a fixed clock (``clock="fixed:MS"``) every check passes."""

import time

import gymnasium as gym
import gymnasium.utils.env_checker as env_checker
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.clocks import WallClock

pytestmark = pytest.mark.filterwarnings("ignore:.*WARN:")  # check_env's advice (wrapped env, infinite bounds)

PARALLEL = [
    "Dubins4DParallel-v0",
    "Dubins4DMapParallel-v0",
    "Dubins3DMazeParallel-v0",
    "QuadrotorRoomParallel-v0",
    "CartPoleParallel-v0",
    "InvertedPendulumParallel-v0",
]
#: the one check the wall clock cannot pass
WALL_CLOCK_FAILS = ["check_step_determinism"]


class LaterEachLap(WallClock):
    """The wall clock on a machine where each lap takes a millisecond longer than the one before:
    as on any machine, two calls never take the same time, but here by more than the 2 ms an env
    that steps in whole physics steps (CartPole's 0.02 s at 10x) would round away."""

    def __init__(self) -> None:
        self.calls = 0
        super().__init__()

    def now(self) -> float:
        self.calls += 1
        return time.perf_counter() + 1e-3 * self.calls**2


def _checks_that_fail(monkeypatch, env) -> tuple[list[str], list[str]]:
    """``check_env(env)`` with each of its checks run on its own: the checks that ran, and those
    that failed (an ``AssertionError``; any other exception is an error of the env)."""
    ran: list[str] = []
    failed: list[str] = []

    def recording(name, check):
        def run(*args, **kwargs):
            ran.append(name)
            try:
                return check(*args, **kwargs)
            except AssertionError:
                failed.append(name)

        return run

    for name, check in list(vars(env_checker).items()):
        if callable(check) and name != "check_env" and (name.startswith("check_") or name.endswith("_checker")):
            monkeypatch.setattr(env_checker, name, recording(name, check))
    env_checker.check_env(env, skip_render_check=True)
    return ran, failed


def _make(env_id: str, **kwargs):
    if env_id == "InvertedPendulumParallel-v0":
        pytest.importorskip("mujoco")
    return gym.make(env_id, **kwargs)


@pytest.mark.parametrize("env_id", PARALLEL)
def test_the_wall_clock_fails_step_determinism_alone(monkeypatch, env_id):
    ran, failed = _checks_that_fail(monkeypatch, _make(env_id, clock=LaterEachLap()))
    assert {"check_reset_seed_determinism", "env_step_passive_checker", "check_returned_data_not_reused"} <= set(ran)
    assert "check_step_determinism" in ran
    assert failed == WALL_CLOCK_FAILS


@pytest.mark.parametrize("env_id", PARALLEL)
def test_check_env_under_the_default_clock_and_a_fixed_one(monkeypatch, env_id):
    env = _make(env_id)
    assert isinstance(env.get_wrapper_attr("clock"), WallClock)  # the default
    ran, failed = _checks_that_fail(monkeypatch, env)
    # the real wall clock: the determinism check fails whenever the two laps differ enough to change
    # the step (they almost always do; an env stepping in whole physics steps can round them equal)
    assert set(failed) <= set(WALL_CLOCK_FAILS)
    monkeypatch.undo()
    env_checker.check_env(_make(env_id, clock="fixed:1"), skip_render_check=True)  # every check passes
