"""``rmm-bench replay`` imports a module a database names only with consent, and that module's
source is part of the run's inputs (issue 49, item 2): a strategy of one's own named inside an
agent's options (``--agent-opt 'lrmm.strategies="+mod:Cls"'``) is refused without
``--trust-module``/``--trust-modules`` (nothing imported), replays ``verified`` with it, and after
its file is edited a rerun starts a new run while a replay of the old one is refused naming the
file.  Runs naming no module of one's own keep their keys."""

from __future__ import annotations

import json
import sqlite3
import sys

import pytest

from rmm_bench import runner
from rmm_bench.cli import main
from rmm_bench.config import AgentRun, file_sha256, run_modules, source_digests
from rmm_envs.user_modules import UserModuleError, import_user_module, named_modules, only_consented

FAST = ["--clock", "fixed:1", "--workers", "1", "--no-progress", "--no-figure"]

#: a strategy module of one's own that leaves a mark each time it is imported
STRATEGY = """
import pathlib

pathlib.Path(__file__).with_name("IMPORTED").open("a").write("x")

from rmm_guardians.lrmm.strategies import Strategy


class Coast(Strategy):
    PARAMS = ()
    MARGIN = {margin}
"""


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """The user's folder: the current directory, not on ``sys.path`` (rmm-bench finds its modules
    there itself); the modules imported from it are forgotten afterwards."""
    monkeypatch.chdir(tmp_path)
    before = set(sys.modules)
    yield tmp_path
    for name in set(sys.modules) - before:
        if name.startswith("consent_"):
            del sys.modules[name]


def _forget(name: str) -> None:
    """As a fresh ``rmm-bench`` process would start: the module not imported, no guardian built."""
    sys.modules.pop(name, None)
    runner._CACHE.clear()


def _runs(out) -> dict[str, dict]:
    with sqlite3.connect(out / "results.db") as db:
        return {k: json.loads(c) for k, c in db.execute("SELECT run_key, config FROM runs")}


def _replay(capsys, out, *extra) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["replay", str(out), "--agent", "lrmm", "--episode", "0,1", "--no-progress", *extra])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_a_strategy_module_named_in_the_options_is_replayed_only_with_consent_and_keyed_by_its_source(folder, capsys):
    module = "consent_rules"
    (folder / f"{module}.py").write_text(STRATEGY.format(margin=1))
    mark = folder / "IMPORTED"
    out = folder / "res"
    cmd = ["--agent", "lrmm", "--agent-opt", f'lrmm.strategies="+{module}:Coast"', "--episodes", "2"]
    assert main([*cmd, "--out", str(out), *FAST]) == 0
    ((key, config),) = _runs(out).items()
    assert config["inputs"][f"{module}.py"] == file_sha256(folder / f"{module}.py")  # its source keys the run

    # the probe: the database names the module, the command line does not -> refused, nothing imported
    _forget(module)
    mark.unlink()
    code, text, err = _replay(capsys, out)
    assert code == 2 and text == ""
    (line,) = err.splitlines()
    assert f"module {module!r}" in line and f"--trust-module {module}" in line and "--trust-modules" in line
    assert not mark.exists()

    # consent, by naming the module or trusting them all: imported and verified
    for consent in (["--trust-module", module], ["--trust-modules"]):
        _forget(module)
        code, text, err = _replay(capsys, out, *consent)
        assert code == 0, err
        assert "episode 0: verified" in text and "episode 1: verified" in text
    assert mark.read_text() == "xx"

    # the module edited: a replay of the old run is refused naming the file, before importing it
    recorded = file_sha256(folder / f"{module}.py")
    (folder / f"{module}.py").write_text(STRATEGY.format(margin=2))
    _forget(module)
    mark.unlink()
    code, text, err = _replay(capsys, out, "--trust-modules")
    assert code == 2 and "verified" not in text + err
    (line,) = err.splitlines()
    assert line.startswith(f"rmm-bench: error: {module}.py: its sha256 is {file_sha256(folder / f'{module}.py')[:12]}")
    assert f"expected {recorded[:12]}..." in line
    assert not mark.exists()

    # ... and the same command starts a new run instead of appending to the old one
    assert main([*cmd, "--out", str(out), *FAST]) == 0
    assert "ran 2 episodes" in capsys.readouterr().out
    runs = _runs(out)
    assert len(runs) == 2 and key in runs


def test_a_module_of_the_agent_or_env_is_still_named_by_its_flag(folder):
    """The modules a run names, and what names each (what a refusal says)."""
    assert run_modules("mine:Guard", "my_env:Line-v0", {"strategies": "+rules:Coast(1), -Commit"}, {}) == {
        "mine": "agent 'mine:Guard'",
        "my_env": "env 'my_env:Line-v0'",
        "rules": "agent option '+rules:Coast(1), -Commit'",
    }


@pytest.mark.parametrize(
    ("value", "modules"),
    [
        ("+evil_strat:Evil", ["evil_strat"]),
        ("SafestCandidate, pkg.mod:Cls(steps=3, name='a:b'), -Commit", ["pkg.mod"]),
        (["a.b:C", {"x": "d:E.F"}], ["a.b", "d"]),
        ("fixed:1", []),  # a clock, not a module
        ("wall", []),
        ("Commit(steps=18)", []),
        ("models/x:y.npz", []),
        ("C:\\models\\m.npz", []),
        (3, []),
    ],
)
def test_what_counts_as_a_module_named_in_an_option(value, modules):
    assert list(named_modules(value)) == modules


def test_runs_that_name_no_module_of_their_own_keep_their_keys():
    """Built-in strategies and clocks name no module: nothing is added to the run's inputs."""
    opts = {"strategies": "-Commit, +Restart(0.3)", "threshold": 0.5}
    assert source_digests("lrmm", "Dubins4DParallel-v0", None, opts, {"clock": "fixed:1"}) == {}
    run = AgentRun("lrmm", opts, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 600.0, False)
    assert "inputs" not in run.as_dict()


def test_while_a_replay_runs_a_module_named_elsewhere_is_refused_the_same_way(folder):
    """A strategy a stored model file names reaches the import without passing the up-front check:
    refused there, naming how to consent; this project's own modules always import."""
    (folder / "consent_elsewhere.py").write_text(STRATEGY.format(margin=1))
    hint = "pass --trust-module {0} or --trust-modules"
    with only_consented({"consent_other"}, hint):
        with pytest.raises(UserModuleError, match=r"module 'consent_elsewhere' is imported only with consent: pass "):
            import_user_module("consent_elsewhere", "strategy 'consent_elsewhere:Coast'")
        assert import_user_module("rmm_guardians.baselines", "guardian").__name__ == "rmm_guardians.baselines"
    assert not (folder / "IMPORTED").exists()
