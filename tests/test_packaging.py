"""What ``pip install`` puts on the import path carries this project's name only, and the suite works
from a user's research repository that holds packages called ``benchmarks``, ``guardians``,
``tests`` and ``rmm`` of its own (docs/decisions/0001-import-names.md)."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from pathlib import Path

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

from tests.layout import PACKAGE_DIRS, ROOT

PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
BIN = Path(sysconfig.get_path("scripts"))


def test_the_package_map_is_the_tests_layout_and_lists_every_package_folder():
    setup = PYPROJECT["tool"]["setuptools"]
    mapped = {name: ROOT / folder for name, folder in setup["package-dir"].items()}
    assert mapped | {"rmm_envs": ROOT / "rmm_envs"} == PACKAGE_DIRS
    folders = {}
    for name, folder in PACKAGE_DIRS.items():
        for init in folder.rglob("__init__.py"):
            rel = init.parent.relative_to(folder).as_posix()
            folders[name + ("" if rel == "." else "." + rel.replace("/", "."))] = init.parent
    # folders of data files
    data = {"rmm_envs.assets", "rmm_envs.assets.maps", "rmm_guardians.lrmm.models", "rmm_bench.manifests"}
    assert set(setup["packages"]) == set(folders) | data
    assert all(name.startswith("rmm_") for name in setup["packages"])


@pytest.mark.heavy
def test_the_wheel_installs_only_names_of_this_project_and_no_development_script(tmp_path):
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0 and "No module named" in done.stderr:  # no setuptools in this interpreter: isolate
        done = subprocess.run(
            [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
            capture_output=True,
            text=True,
        )
    assert done.returncode == 0, done.stderr
    (wheel,) = tmp_path.glob("rmm_envs-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    top = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert top == {"rmm_envs", "rmm_guardians", "rmm_bench"}
    assert not [n for n in names if "perf_" in n or "check_behaviour" in n or n.startswith(("benchmarks/", "tests/"))]
    for data in (
        "rmm_guardians/lrmm/models/dubins4d.npz",
        "rmm_envs/assets/quadrotor.urdf",
        "rmm_envs/assets/maps/example.json",
    ):
        assert data in names
    meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(meta).decode()
    assert "License-Expression: MIT" in text


GUARDIAN = textwrap.dedent("""
    from rmm_guardians import Guardian


    class Never(Guardian):
        \"\"\"Never takes control.\"\"\"

        def act(self, observation, info):
            return self.action_space.inactive()
""")


@pytest.fixture
def research_repo(tmp_path):
    """A user's repository: packages of its own named like ours, and a module with a guardian."""
    for pkg in ("benchmarks", "guardians", "tests", "rmm"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text(
            "raise ImportError('the user package was imported')\n" if pkg != "tests" else ""
        )
    (tmp_path / "mymod.py").write_text(GUARDIAN)
    (tmp_path / "broken.py").write_text("import a_module_nobody_has_26\n")
    (tmp_path / "shadowed").mkdir()
    (tmp_path / "shadowed" / "__init__.py").write_text("")
    (tmp_path / "shadowed.py").write_text(GUARDIAN)  # the folder wins on the import path
    return tmp_path


def _run(cmd, cwd):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env, timeout=300)


@pytest.mark.heavy
def test_rmm_bench_with_two_workers_from_a_repository_with_same_named_packages(research_repo):
    done = _run(
        [
            str(BIN / "rmm-bench"),
            "--agent",
            "inactive,mymod:Never",
            "--episodes",
            "4",
            "--workers",
            "2",
            "--clock",
            "fixed:1",
            "--no-progress",
            "--no-figure",
            "--out",
            "res",
        ],
        research_repo,
    )
    assert done.returncode == 0, done.stderr
    table = (research_repo / "res" / "table_I.md").read_text()
    rows = {line.split(" | ")[0].strip("| "): line for line in table.splitlines() if line.startswith("| ")}
    assert "mymod:Never" in rows and "inactive" in rows
    assert rows["mymod:Never"].split(" | ")[3] == "4"  # four episodes, none an error
    assert "error" not in done.stderr.lower()
    # the Python API and the other commands from the same directory
    api = _run(
        [sys.executable, "-c", "import rmm_bench, rmm_guardians, rmm_envs; print(len(rmm_bench.load_results('res')))"],
        research_repo,
    )
    assert api.returncode == 0 and api.stdout.strip() == "8", api.stderr
    data = _run(
        [
            str(BIN / "rmm-datagen"),
            "--env",
            "Dubins4DGuarded-v0",
            "--configs",
            "1",
            "--samples-per-config",
            "2",
            "--branches",
            "2",
            "--depth",
            "1",
            "--no-progress",
            "--out",
            "d",
        ],
        research_repo,
    )
    assert data.returncode == 0 and (research_repo / "d" / "metadata.json").is_file(), data.stderr
    assert _run([str(BIN / "rmm-train"), "--help"], research_repo).returncode == 0


@pytest.mark.slow
def test_ray_workers_from_a_repository_with_same_named_packages(research_repo):
    pytest.importorskip("ray")
    done = _run(
        [
            str(BIN / "rmm-bench"),
            "--agent",
            "inactive,mymod:Never",
            "--episodes",
            "4",
            "--workers",
            "2",
            "--backend",
            "ray",
            "--clock",
            "fixed:1",
            "--no-progress",
            "--no-figure",
            "--out",
            "res",
        ],
        research_repo,
    )
    assert done.returncode == 0, done.stderr
    rows = [
        line for line in (research_repo / "res" / "table_I.md").read_text().splitlines() if line.startswith("| mymod")
    ]
    assert len(rows) == 1 and rows[0].split(" | ")[3] == "4" and rows[0].split(" | ")[-2] == "0"  # 4 episodes, 0 errors


@pytest.mark.parametrize(
    ("agent", "says"),
    [
        (
            "nomod26:X",
            "guardian 'nomod26:X': cannot import module 'nomod26': no module named 'nomod26' in the current "
            "directory ({cwd}) or the installed packages",
        ),
        (
            "broken:X",
            "guardian 'broken:X': cannot import module 'broken' (from broken.py): ModuleNotFoundError: No module "
            "named 'a_module_nobody_has_26'",
        ),
        (
            "shadowed:Never",
            "guardian 'shadowed:Never': module 'shadowed' (from shadowed/__init__.py) has no attribute 'Never'",
        ),
    ],
)
def test_a_user_module_that_cannot_be_used_is_one_line_naming_it_and_its_file(
    research_repo, agent, says, monkeypatch, capsys
):
    from rmm_bench.cli import main

    monkeypatch.chdir(research_repo)
    monkeypatch.setattr(sys, "path", list(sys.path))
    for name in ("mymod", "broken", "shadowed"):
        monkeypatch.delitem(sys.modules, name, raising=False)
    assert main(["--agent", agent, "--episodes", "1", "--no-progress", "--no-figure", "--out", "r"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"rmm-bench: error: {says.format(cwd=research_repo)}"]


def test_an_env_module_that_fails_to_import_is_named_with_its_file(research_repo, monkeypatch, capsys):
    from rmm_bench.cli import main

    monkeypatch.chdir(research_repo)
    monkeypatch.setattr(sys, "path", list(sys.path))
    monkeypatch.delitem(sys.modules, "broken", raising=False)
    assert (
        main(["--agent", "inactive", "--env", "broken:Foo-v0", "--episodes", "1", "--no-progress", "--out", "r"]) == 2
    )
    assert capsys.readouterr().err.strip() == (
        "rmm-bench: error: --env 'broken:Foo-v0': cannot import module 'broken' "
        "(from broken.py): ModuleNotFoundError: No module named "
        "'a_module_nobody_has_26'"
    )
