"""Envs of other packages in ``rmm-bench`` (issue 26, item 4): a package's ``gymnasium.envs``
entry point registers its env in the parent and in every worker, and an env that a worker
cannot register is a failure of the run named as such (exit status 1, the env id and the
import error in the message, error kind ``env`` in the store), never a guardian error."""

from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import pytest

from rmm_envs.env_plugins import EnvUnavailable, resolve_env_id

PLUGIN = """
import gymnasium as gym

CALLS = []


def register():
    CALLS.append(1)
    if "PlugCircles-v0" not in gym.registry:
        gym.register(id="PlugCircles-v0", entry_point="rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv")
"""

BROKEN_PLUGIN = """
def register():
    raise RuntimeError("the plugin's simulator is not installed")
"""

WORKER_ONLY_FAILURE = """
import multiprocessing

import gymnasium as gym

if multiprocessing.parent_process() is not None:  # a spawned worker
    raise ImportError("the licence server of MyEnv is not reachable from worker processes")
gym.register(id="MyEnv-v0", entry_point="rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv")
"""


def _dist(root: Path, name: str, module: str, source: str) -> None:
    """An installed distribution in ``root``: its module and a dist-info with one entry point."""
    (root / f"{module}.py").write_text(source)
    info = root / f"{name}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[gymnasium.envs]\n{name} = {module}:register\n")


def _bench(cwd: Path, *args: str, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).parent / "rmm-bench"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    return subprocess.run(
        [str(exe), *args, "--clock", "fixed:1", "--no-progress", "--no-figure", "--out", str(cwd / "res")],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )


def test_an_entry_point_registers_its_env_when_the_id_is_asked_for(tmp_path, monkeypatch):
    _dist(tmp_path, "plugdemo", "plugdemo_envs", PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "PlugCircles-v0" not in gym.registry
    try:
        assert resolve_env_id("PlugCircles-v0") == "PlugCircles-v0"
        assert "PlugCircles-v0" in gym.registry
        import plugdemo_envs

        assert plugdemo_envs.CALLS == [1]
        resolve_env_id("PlugCircles-v0")  # loaded once per process
        assert plugdemo_envs.CALLS == [1]
    finally:
        gym.registry.pop("PlugCircles-v0", None)
        sys.modules.pop("plugdemo_envs", None)


def test_a_failing_entry_point_is_named_in_the_error_of_the_id_it_left_unregistered(tmp_path, monkeypatch):
    _dist(tmp_path, "brokenplug", "brokenplug_envs", BROKEN_PLUGIN)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(EnvUnavailable) as e:
        resolve_env_id("Missing26-v0")
    msg = str(e.value)
    assert msg.startswith("--env 'Missing26-v0' is not a registered Gymnasium env")
    assert "entry point 'brokenplug_envs:register' raised RuntimeError: the plugin's simulator is not installed" in msg


def test_a_mistyped_id_is_answered_with_the_nearest_registered_one():
    with pytest.raises(
        EnvUnavailable,
        match=r"^--env 'Dubins4DCirclesParalel-v0' is not a registered Gymnasium env "
        r"\(did you mean 'Dubins4DParallel-v0'\?\); this package registers ",
    ):
        resolve_env_id("Dubins4DCirclesParalel-v0")
    with pytest.raises(EnvUnavailable, match=r"^--env 'Zzqx-v0' is not a registered Gymnasium env; this package"):
        resolve_env_id("Zzqx-v0")


def test_module_ids_are_resolved_to_the_id_the_module_registers(tmp_path, monkeypatch):
    (tmp_path / "regmod26.py").write_text(
        'import gymnasium as gym\ngym.register(id="Reg26-v0", entry_point="rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv")\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        assert resolve_env_id("regmod26:Reg26-v0") == "Reg26-v0"
        with pytest.raises(
            EnvUnavailable, match=r"importing 'regmod26' \(from .*regmod26\.py\) registered no env 'Other-v0'"
        ):
            resolve_env_id("regmod26:Other-v0")
        with pytest.raises(EnvUnavailable, match=r"an env id must be a non-empty string, got 3"):
            resolve_env_id(3)
    finally:
        gym.registry.pop("Reg26-v0", None)
        sys.modules.pop("regmod26", None)


@pytest.mark.heavy
def test_rmm_bench_runs_an_entry_point_env_in_every_worker(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    _dist(site, "plugdemo", "plugdemo_envs", PLUGIN)
    res = _bench(
        tmp_path, "--env", "PlugCircles-v0", "--agent", "inactive", "--episodes", "4", "--workers", "2", pythonpath=site
    )
    assert res.returncode == 0, res.stderr[-2000:]
    row = next(line for line in res.stdout.splitlines() if line.startswith("| inactive"))
    assert "| 4 |" in row


@pytest.mark.heavy
def test_an_env_a_worker_cannot_register_fails_the_run_naming_the_env_and_the_import_error(tmp_path):
    (tmp_path / "workerfail.py").write_text(WORKER_ONLY_FAILURE)
    res = _bench(tmp_path, "--env", "workerfail:MyEnv-v0", "--agent", "inactive", "--episodes", "4", "--workers", "2")
    assert res.returncode == 1, res.stdout[-2000:]
    line = next(x for x in res.stderr.splitlines() if "could not make the env in their worker" in x)
    assert line.startswith(
        "rmm-bench: --env workerfail:MyEnv-v0: 4 episodes could not make the env in their worker, "
        "a failure of the run, not of a guardian"
    )
    assert (
        "cannot import module 'workerfail' (from workerfail.py): "
        "ImportError: the licence server of MyEnv is not reachable from worker processes"
    ) in line
    assert "guardian error" not in res.stderr
    assert (
        "INCOMPLETE: episodes with a result: inactive 0 of 4 (4 unable to make the env in their worker;"
    ) in res.stdout
    with sqlite3.connect(tmp_path / "res" / "results.db") as db:
        kinds = db.execute("SELECT outcome, error_kind, COUNT(*) FROM episodes GROUP BY 1, 2").fetchall()
    assert kinds == [("error", "env", 4)]


CARTPOLE_PLUGIN = """
import gymnasium as gym


def register():
    if "PlugCartPole-v0" not in gym.registry:
        gym.register(id="PlugCartPole-v0", entry_point="gymnasium.envs.classic_control:CartPoleEnv",
                     max_episode_steps=200)
"""


@pytest.mark.slow  # rmm-bench's entry-point drill above runs in the default suite
def test_rmm_datagen_labels_an_entry_point_env_in_every_worker(tmp_path):
    site = tmp_path / "site"
    site.mkdir()
    _dist(site, "plugcart", "plugcart_envs", CARTPOLE_PLUGIN)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"} | {"PYTHONPATH": str(site)}
    exe = Path(sys.executable).parent / "rmm-datagen"
    res = subprocess.run(
        [
            str(exe),
            "--env",
            "PlugCartPole-v0",
            "--configs",
            "4",
            "--samples-per-config",
            "8",
            "--branches",
            "4",
            "--configs-per-shard",
            "2",
            "--workers",
            "2",
            "--no-progress",
            "--out",
            str(tmp_path / "data"),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        env=env,
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert "32 labelled samples" in res.stdout
