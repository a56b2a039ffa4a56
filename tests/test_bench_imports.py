"""``rmm-bench --agent module:Class`` and ``--env module:Id`` import from the directory the
command runs in, in the parent and in every worker (issue 27), after the installed packages
(tests/test_user_folders.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

GUARD = """
from rmm_guardians.base import Guardian


class Steady(Guardian):
    name = "steady"

    def act(self, observation, info):
        return self.action_space.inactive()
"""
ENV = """
import gymnasium as gym

gym.register(id="MyCircles-v0", entry_point="rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv")
"""


def _bench(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).parent / "rmm-bench"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(
        [str(exe), *args, "--clock", "fixed:1", "--no-progress", "--no-figure", "--out", str(cwd / "res")],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )


@pytest.fixture(scope="module")
def current_directory_run(once_per_run):
    """One two-worker run (once per test run) whose guardian and env both come from modules in the
    directory it runs in: the guardian counts its act() calls per process (``WARM`` below)."""

    def make(cwd):
        (cwd / "warm_guard.py").write_text(WARM)
        (cwd / "my_env.py").write_text(ENV)
        res = _bench(
            cwd,
            "--agent",
            "warm_guard:CountsCalls",
            "--env",
            "my_env:MyCircles-v0",
            "--episodes",
            "4",
            "--workers",
            "2",
        )
        (cwd / "run.json").write_text(
            json.dumps({"returncode": res.returncode, "stdout": res.stdout, "stderr": res.stderr})
        )

    cwd = once_per_run("current_directory_run", make)
    return cwd, subprocess.CompletedProcess([], **json.loads((cwd / "run.json").read_text()))


@pytest.mark.heavy
def test_agent_and_env_modules_are_found_in_the_current_directory_by_every_worker(current_directory_run):
    _, res = current_directory_run
    assert res.returncode == 0, res.stderr[-2000:]
    row = next(line for line in res.stdout.splitlines() if line.startswith("| warm_guard:CountsCalls"))
    assert "| 4 |" in row and "| 0 | 0 |" in row  # four episodes, no errors


@pytest.mark.slow  # a Ray cluster of its own (25-35 s); the local pool's test of the same promise is above
def test_ray_workers_find_the_current_directory_s_modules_too(tmp_path):
    (tmp_path / "my_guard.py").write_text(GUARD)
    (tmp_path / "my_env.py").write_text(ENV)
    res = _bench(
        tmp_path, "--agent", "my_guard:Steady", "--env", "my_env:MyCircles-v0", "--episodes", "4", "--backend", "ray"
    )
    assert res.returncode == 0, res.stderr[-2000:]
    row = next(line for line in res.stdout.splitlines() if line.startswith("| my_guard:Steady"))
    assert "| 4 |" in row and "| 0 | 0 |" in row  # four episodes, no errors


def test_a_module_that_is_not_there_exits_2_naming_it(tmp_path):
    res = _bench(tmp_path, "--agent", "no_such_guard:X", "--episodes", "1")
    assert res.returncode == 2
    assert "cannot import module 'no_such_guard'" in res.stderr
    res = _bench(tmp_path, "--env", "no_such_env:E-v0", "--episodes", "1")
    assert res.returncode == 2
    assert "--env 'no_such_env:E-v0': cannot import module 'no_such_env'" in res.stderr
    (tmp_path / "empty_env.py").write_text("")
    res = _bench(tmp_path, "--env", "empty_env:E-v0", "--episodes", "1")
    assert res.returncode == 2 and "importing 'empty_env' (from empty_env.py) registered no env 'E-v0'" in res.stderr


WARM = """
from rmm_guardians.base import Guardian

CALLS = 0  # act() calls in this worker process


class CountsCalls(Guardian):
    name = "counts-calls"

    def reset(self, **kwargs):
        super().reset(**kwargs)
        self.calls_before = CALLS

    def act(self, observation, info):
        global CALLS
        CALLS += 1
        return self.action_space.inactive()

    def stats(self):
        return {"calls_before": self.calls_before}
"""


def test_each_workers_first_timed_decision_comes_after_an_untimed_warm_up(current_directory_run):
    """Every episode, the first of each worker included, starts with act() already called in
    that process: compiling or loading a guardian's kernels is never a timed decision."""
    import json

    from rmm_bench import load_results

    cwd, res = current_directory_run
    assert res.returncode == 0, res.stderr[-2000:]
    df = load_results(cwd / "res")
    calls = [json.loads(s)["calls_before"] for s in df.guardian_stats]
    assert len(calls) == 4 and min(calls) >= 1


def test_the_cbf_warm_up_reaches_the_qp_and_the_recovery_then_reset_forgets_it():
    """cbf's first decision far from every obstacle solves no QP; its warm-up solves two (the
    compiled matrix fill) and computes a recovery, and the episode's counters start at zero."""
    import gymnasium as gym

    from rmm_guardians import make_guardian

    env = gym.make("Dubins4DGuarded-v0")
    obs, info = env.reset(seed=0)
    g = make_guardian("cbf")
    kw = dict(
        seed=0,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    g.reset(**kw)
    g.act(obs, info)
    assert g.stats()["qp_solves"] == 0  # the first decision alone would leave the QP uncompiled
    g.reset(**kw)
    g.warm_up(obs, info)
    assert g.stats()["qp_solves"] == 2
    g.reset(**kw)
    assert g.stats()["qp_solves"] == 0 and g.stats()["recovery_entries"] == 0
