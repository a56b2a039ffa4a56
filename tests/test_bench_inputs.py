"""A run reads the user's own code: editing the module of a ``module:Class`` agent or a ``module:Id``
env starts a new run (its source file is part of the run's ``inputs``), and ``rmm-bench replay``
refuses a changed one, naming it.  An exception the env itself raises (its ``reset`` or ``step``,
e.g. its driver) is the env's error, with the innermost frames of its traceback, never the
guardian's."""

from __future__ import annotations

import itertools
import json
import sqlite3
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from rmm_bench.cli import main
from rmm_bench.config import AgentRun, EpisodeTask, file_sha256, source_digests
from rmm_bench.runner import TRACEBACK_CHARS, _traceback_text, play_episode
from rmm_guardians.base import Guardian

FAST = ["--clock", "fixed:1", "--no-progress", "--no-figure", "--workers", "1"]
_ids = itertools.count()

#: a simulator of one's own made a guarded env (rmm_envs.envs.any_env), registered on import; RADIUS
#: stands for what one edits (an obstacle's radius), RAISE_AT for a driver that raises at that call
SIMULATOR = """
import gymnasium as gym
import numpy as np

from rmm_envs.envs.any_env import guarded

RADIUS = {radius}
RAISE_AT = {raise_at}
CALLS = [0]


class Line:
    dt = 0.25
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.x = 0.0

    def get_state(self):
        return np.array([self.x])

    def set_state(self, state):
        self.x = float(state[0])

    def step(self, action):
        self.x += self.dt * float(action[0])
        return self.x >= RADIUS

    def state_failed(self, states):
        return np.asarray(states)[:, 0] >= RADIUS

    def sample_states(self, rng, n):
        return rng.uniform(-1.0, 1.0, (n, 1))


def driver(obs):
    CALLS[0] += 1
    if CALLS[0] == RAISE_AT:
        raise RuntimeError("the driver lost its map")
    return np.array([1.0], np.float32)


def stop(obs):
    return np.array([0.0], np.float32)


def never(obs):
    return False


def entry(clock=None, render_mode=None):
    return guarded(Line(), driver=driver, safe_default=stop, success=never, max_episode_sim_time=5.0,
                   clock=clock, render_mode=render_mode)


gym.register("{env_id}", entry_point=entry)
"""

GUARDIAN = """
from rmm_guardians.base import Guardian

MARGIN = {margin}


class Cautious(Guardian):
    name = "cautious"

    def act(self, obs, info):
        return self.action_space.inactive()
"""


@pytest.fixture
def project(tmp_path, monkeypatch):
    """The user's folder (the current directory, where rmm-bench imports their modules from); the
    modules written there are forgotten afterwards."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        if name.startswith(("usersim_", "userguard_")):
            del sys.modules[name]


def _simulator(folder, radius=1.0, raise_at=0) -> tuple[str, str]:
    """A module registering a guarded env of its own: (module name, --env value)."""
    n = next(_ids)
    module, env_id = f"usersim_{n}", f"UserLine{n}-v0"
    _write_simulator(folder, module, env_id, radius, raise_at)
    return module, f"{module}:{env_id}"


def _write_simulator(folder, module, env_id, radius, raise_at) -> None:
    (folder / f"{module}.py").write_text(SIMULATOR.format(radius=radius, raise_at=raise_at, env_id=env_id))


def _runs(out) -> dict[str, dict]:
    with sqlite3.connect(out / "results.db") as db:
        return {k: json.loads(c) for k, c in db.execute("SELECT run_key, config FROM runs")}


def test_builtin_guardians_and_envs_read_no_source_file_so_their_keys_stay():
    assert source_digests("inactive", "Dubins4DParallel-v0") == {}
    assert source_digests("lrmm", "CartPoleParallel-v0") == {}
    run = AgentRun("inactive", {}, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 600.0, False)
    assert "inputs" not in run.as_dict()  # the stored configuration (and key) of a built-in run is unchanged


def test_a_builtin_run_keeps_its_key_through_the_checks(tmp_path):
    from rmm_bench.run_args import parse_run
    from rmm_bench.run_plan import applicable

    cfg = parse_run(["--agent", "inactive,brakes", "--out", str(tmp_path), *FAST], "")
    before = {a: r.key for a, r in cfg.agent_runs().items()}
    checked, _ = applicable(cfg)
    assert checked.agent_inputs == {"inactive": {}, "brakes": {}}
    assert {a: r.key for a, r in checked.agent_runs().items()} == before


def test_the_module_s_own_file_is_read_a_package_s_init(project):
    (project / "userguard_pkg").mkdir()
    (project / "userguard_pkg" / "__init__.py").write_text(GUARDIAN.format(margin=1))
    (project / "userguard_mod.py").write_text(GUARDIAN.format(margin=2))
    import userguard_mod  # noqa: F401
    import userguard_pkg  # noqa: F401

    init = str(project / "userguard_pkg" / "__init__.py")
    assert source_digests("userguard_pkg:Cautious", "Dubins4DParallel-v0") == {
        "userguard_pkg/__init__.py": file_sha256(init)
    }
    assert source_digests("userguard_mod:Cautious", "Dubins4DParallel-v0") == {
        "userguard_mod.py": file_sha256(project / "userguard_mod.py")
    }
    # relative to the folder rmm-bench ran in (a worker's import path), absolute outside it
    assert list(source_digests("userguard_mod:Cautious", "x", base=str(project / "userguard_pkg"))) == [
        str(project / "userguard_mod.py")
    ]


def test_editing_your_simulator_starts_a_new_run_instead_of_reusing_stale_episodes(project, capsys):
    module, env = _simulator(project, radius=1.0)
    cmd = ["--env", env, "--agent", "inactive", "--episodes", "2", "--out", str(project / "res"), *FAST]
    assert main(cmd) == 0
    assert main(cmd) == 0  # nothing changed: answered from the store
    assert "reused 2 stored episodes: none left to run" in capsys.readouterr().out
    ((first_key, first),) = _runs(project / "res").items()
    assert first["inputs"] == {f"{module}.py": file_sha256(project / f"{module}.py")}

    _write_simulator(project, module, env.partition(":")[2], radius=0.6, raise_at=0)  # an obstacle moved
    assert main(cmd) == 0
    captured = capsys.readouterr()
    assert "ran 2 episodes" in captured.out and "none left to run" not in captured.out
    assert (
        f"rmm-bench: inactive: 2 episodes in {project / 'res' / 'results.db'} were run with other files: "
        f"{module}.py (sha256 {first['inputs'][f'{module}.py'][:12]} then, "
    ) in captured.err
    runs = _runs(project / "res")
    assert len(runs) == 2 and first_key in runs
    (new,) = (c for k, c in runs.items() if k != first_key)
    assert new["inputs"] == {f"{module}.py": file_sha256(project / f"{module}.py")}


def test_editing_your_guardian_starts_a_new_run_and_replay_refuses_the_edited_module(project, capsys):
    (project / "userguard_a.py").write_text(GUARDIAN.format(margin=0.3))
    out = project / "res"
    agent = "userguard_a:Cautious"
    cmd = ["--env", "Dubins4DParallel-v0", "--agent", agent, "--episodes", "1", "--out", str(out), *FAST]
    assert main(cmd) == 0
    capsys.readouterr()
    # the module as the run read it: the replay verifies (its source digest agrees with the run's)
    assert main(["replay", str(out), "--agent", agent, "--episode", "0", "--no-progress"]) == 0
    assert "episode 0: verified" in capsys.readouterr().out

    recorded = file_sha256(project / "userguard_a.py")
    (project / "userguard_a.py").write_text(GUARDIAN.format(margin=0.5))  # the guardian edited
    assert main(["replay", str(out), "--agent", agent, "--episode", "0", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert (
        f"userguard_a.py: its sha256 is {file_sha256(project / 'userguard_a.py')[:12]}..., "
        f"expected {recorded[:12]}... (the file the run read)"
    ) in err
    assert "verified" not in err and "cannot be verified" not in err  # never blamed on non-determinism

    assert main(cmd) == 0
    assert "ran 1 episode" in capsys.readouterr().out
    assert len(_runs(out)) == 2


def test_a_worker_runs_no_episode_when_the_module_changed_after_the_run_was_keyed(project):
    (project / "userguard_b.py").write_text(GUARDIAN.format(margin=1))
    agent = "userguard_b:Cautious"
    run = AgentRun(
        agent, {}, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 600.0, False, inputs={"userguard_b.py": "0" * 64}
    )
    task = EpisodeTask(run=run, run_key=run.key, episode=0, seed=1, import_path=(str(project),))
    result = play_episode(task).result
    assert (result.outcome, result.error_kind) == ("error", "input_changed")
    assert result.error.startswith("InputChanged: userguard_b.py (sha256 000000000000... when the run was keyed")


def test_an_exception_of_the_env_s_driver_is_the_env_s_error_with_the_frame_that_raised(project, capsys):
    module, env = _simulator(project, raise_at=3)
    out = project / "res"
    status = main(["--env", env, "--agent", "inactive", "--episodes", "1", "--out", str(out), *FAST])
    captured = capsys.readouterr()
    assert status == 1
    with sqlite3.connect(out / "results.db") as db:
        ((outcome, kind, error),) = db.execute("SELECT outcome, error_kind, error FROM episodes").fetchall()
    assert (outcome, kind) == ("error", "env")
    lines = error.splitlines()
    assert lines[0] == "RuntimeError: the driver lost its map"
    assert lines[1] == f"raised by the env {env} in its step(), not by the guardian"
    assert f"{module}.py" in error and ", in driver" in error  # the user's frame, under Gymnasium's wrappers
    assert 'raise RuntimeError("the driver lost its map")' in error
    assert len(error) <= 500 + len(lines[1]) + 2 + TRACEBACK_CHARS
    assert "guardian error" not in captured.err and "fix the guardian" not in captured.err
    assert (
        f"rmm-bench: --env {env}: 1 episodes ended in an error of the env itself (its reset or step, e.g. its "
        "driver), not of a guardian, and have no result (first, episode 0: RuntimeError: the driver lost its map"
    ) in captured.err


class _ResetFails(gym.Env):
    observation_space = gym.spaces.Box(-1.0, 1.0, (1,))
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        raise KeyError("no such map")


class BadAction(Guardian):
    """Returns an action the env's action space refuses (active_ctrl must be 0 or 1)."""

    name = "bad-action"

    def act(self, obs, info):
        return self.action_space.inactive() | {"active_ctrl": 7}


def _task(agent: str) -> EpisodeTask:
    run = AgentRun(agent, {}, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 600.0, False)
    return EpisodeTask(run=run, run_key=run.key, episode=0, seed=1)


def test_an_env_reset_that_raises_is_the_env_s_error():
    result = play_episode(_task("inactive"), env=_ResetFails()).result
    assert (result.outcome, result.error_kind) == ("error", "env")
    assert result.error.splitlines()[:2] == [
        "KeyError: 'no such map'",
        "raised by the env Dubins4DParallel-v0 in its reset(), not by the guardian",
    ]


def test_an_action_the_env_refuses_stays_the_guardian_s_error():
    result = play_episode(_task("tests.test_bench_inputs:BadAction")).result
    assert (result.outcome, result.error_kind) == ("error", "guardian")
    assert "active_ctrl" in result.error.splitlines()[0] and "raised by the env" not in result.error


def test_a_stored_traceback_keeps_its_innermost_frames_within_the_limit():
    def deep(n):  # deep and through alternate: no two frames in a row alike (which a traceback folds)
        if n == 0:
            raise ValueError("innermost")
        return through(n - 1)

    def through(n):
        return deep(n)

    try:
        deep(80)
    except ValueError as e:
        text = _traceback_text(e)
    assert len(text) <= TRACEBACK_CHARS
    assert text.startswith("Traceback (most recent call last):\n  ... ")
    assert "outer frames left out" in text
    assert text.rstrip().endswith("ValueError: innermost")
    assert 'raise ValueError("innermost")' in text

    try:
        raise OSError("x" * 5000)
    except OSError as e:
        assert len(_traceback_text(e)) <= TRACEBACK_CHARS
    assert np.isfinite(TRACEBACK_CHARS)


def test_shipped_files_are_named_by_their_place_in_the_package(tmp_path):
    """A shipped model is recorded as package/relative/path, so the same run has the same key on
    every machine and checkout (what merge and compare across machines rest on)."""
    import rmm_guardians.lrmm
    from rmm_bench.config import portable_path, resolve_input

    model = Path(rmm_guardians.lrmm.__file__).parent / "models" / "dubins4d_act.npz"
    key = portable_path(str(model))
    assert key == "rmm_guardians/lrmm/models/dubins4d_act.npz"
    assert resolve_input(key) == model.resolve()
    outside = tmp_path / "mine.npz"
    outside.write_bytes(b"x")
    assert portable_path(str(outside)) == str(outside) and resolve_input(str(outside)) == outside
