"""The current directory is searched for the modules a user names without shadowing installed
packages (issue 49, item 6): ``rmm-bench`` (every subcommand, and its workers) and ``rmm-datagen``
find ``my_guard.py`` and the helper beside it, but never import a ``tqdm.py``, ``pyarrow.py`` or
``multiprocessing.py`` there in place of the real ones; a module named like an installed one is
refused in one line naming both."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from rmm_envs.user_modules import UserModuleError, import_user_module, user_folders

BIN = Path(sys.executable).parent

#: what the user keeps beside their guardian: files named like this project's dependencies (and
#: Python's own multiprocessing, which a spawned worker imports while it starts)
SHADOWS = ("tqdm", "pyarrow", "pandas", "multiprocessing")
MARK = "import pathlib\npathlib.Path(__file__).with_name('SHADOWED_' + __name__).write_text('x')\n"

GUARD = """
from rmm_guardians.base import Guardian

import my_helper  # a module beside it, found in the same folder


class MyGuardian(Guardian):
    name = "mine"

    def act(self, observation, info):
        return self.action_space.inactive() if my_helper.IDLE else None
"""
FAILURE = """
import numpy as np

import my_helper


def too_fast(states):
    return np.abs(states[:, 1]) > my_helper.LIMIT
"""


def _cli(cwd: Path, exe: str, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONSAFEPATH")}
    return subprocess.run([str(BIN / exe), *args], cwd=cwd, capture_output=True, text=True, timeout=600, env=env)


def _folder(tmp_path: Path) -> Path:
    for name in SHADOWS:
        (tmp_path / f"{name}.py").write_text(MARK)
    (tmp_path / "my_guard.py").write_text(GUARD)
    (tmp_path / "my_helper.py").write_text("IDLE = True\nLIMIT = 6.0\n")
    (tmp_path / "pend_failure.py").write_text(FAILURE)
    return tmp_path


def _shadowed(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.glob("SHADOWED_*"))


@pytest.mark.heavy
def test_no_command_imports_a_file_of_the_current_directory_in_place_of_an_installed_package(tmp_path):
    cwd = _folder(tmp_path)
    agents = "inactive,my_guard:MyGuardian"
    res = _cli(cwd, "rmm-bench", "--agent", agents, "--episodes", "2", "--workers", "2", "--clock", "fixed:1",
               "--no-progress", "--no-figure", "--out", "res")  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    assert "| my_guard:MyGuardian |" in res.stdout  # found here, with its helper, by both workers
    for args in (
        ("replay", "res", "--agent", "my_guard:MyGuardian", "--episode", "0,1", "--no-progress"),
        ("compare", "res", "--agent", agents),
        ("export", "res", "--format", "parquet", "--table", "episodes.parquet"),
        ("report", "res"),
    ):
        res = _cli(cwd, "rmm-bench", *args)
        assert res.returncode == 0, (args, res.stderr[-2000:])
    assert "verified: 2 episodes" in _cli(cwd, "rmm-bench", "replay", "res", "--agent", "my_guard:MyGuardian",
                                          "--episode", "0,1", "--no-progress").stdout  # fmt: skip
    res = _cli(cwd, "rmm-datagen", "--env", "Pendulum-v1", "--configs", "2", "--configs-per-shard", "1",
               "--samples-per-config", "4", "--branches", "2", "--workers", "2", "--no-progress", "--out", "data",
               "--failure", "pend_failure:too_fast")  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    assert _shadowed(cwd) == []


@pytest.mark.heavy
def test_a_module_you_name_that_an_installed_one_would_hide_is_one_line_naming_both(tmp_path):
    (tmp_path / "numpy.py").write_text(MARK + "class X:\n    pass\n")
    res = _cli(tmp_path, "rmm-bench", "--agent", "numpy:X", "--episodes", "1", "--out", "res")
    assert res.returncode == 2
    (line,) = res.stderr.splitlines()
    installed = Path(importlib.util.find_spec("numpy").origin)
    assert f"module 'numpy' is both your {tmp_path / 'numpy.py'} and the installed 'numpy' ({installed})" in line
    assert _shadowed(tmp_path) == [] and not (tmp_path / "res").exists()


def test_the_folder_comes_after_the_installed_packages_and_serves_only_what_is_named(tmp_path, monkeypatch):
    monkeypatch.chdir(_folder(tmp_path))
    (tmp_path / "json.py").write_text(MARK)
    (tmp_path / "only_here_41.py").write_text(MARK)
    path = list(sys.path)
    with user_folders([str(tmp_path)]):
        assert sys.path == path  # nothing put in front of the installed packages
        mine = import_user_module("my_guard", "guardian 'my_guard:MyGuardian'")
        assert mine.__file__ == str(tmp_path / "my_guard.py") and mine.my_helper.IDLE is True
        with pytest.raises(ModuleNotFoundError):  # this project's code asking for it: not served from here
            importlib.import_module("only_here_41")
        with pytest.raises(UserModuleError, match=r"module 'json' is both your .*json.py and the installed 'json'"):
            import_user_module("json", "guardian 'json:Foo'")
    assert _shadowed(tmp_path) == []
    for name in ("my_guard", "my_helper"):
        sys.modules.pop(name, None)
    with pytest.raises(UserModuleError, match="no module named 'my_guard'"):  # the folder is the command's only
        import_user_module("my_guard", "guardian 'my_guard:MyGuardian'")


def test_ctrl_c_in_any_subcommand_is_one_line_and_exit_130(monkeypatch, capsys):
    from rmm_bench import cli

    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_command", interrupted)
    assert cli.main(["compare", "res"]) == 130
    assert (
        capsys.readouterr().err == "rmm-bench: interrupted (Ctrl-C) during compare; rerun the same command to finish\n"
    )


def test_ctrl_c_in_rmm_datagen_is_one_line_and_exit_130(monkeypatch, capsys):
    from rmm_envs.risk import datagen

    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(datagen, "_main", interrupted)
    assert datagen.main(["--env", "Pendulum-v1", "--out", "x"]) == 130
    assert capsys.readouterr().err == "rmm-datagen: interrupted (Ctrl-C); rerun the same command to finish\n"
