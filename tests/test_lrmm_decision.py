"""rmm_guardians.lrmm.decision: each model's decision is one text file beside it, the guardian's only
source; the shipped decisions resolve exactly as before they moved there; the file round-trips; bad
files, stale files and decisions left inside old model files are refused in one line."""

from __future__ import annotations

import ast
import fnmatch
import json
import math
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
import tomllib
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_guardians.lrmm.decision import (
    Decision,
    decision_path,
    is_shipped,
    main,
    read_decision,
    set_decision,
    to_toml,
    write_decision,
)
from rmm_guardians.lrmm.guardian import LRMMGuardian, LRMMPaperGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.shipped import SHIPPED, SHIPPED_BY_SYSTEM, default_model_path, models_dir
from rmm_guardians.lrmm.strategies import strategy_specs

ROOT = Path(__file__).resolve().parent.parent
#: every shipped env id x guardian x preset x model variant, resolved by the code before the
#: decisions moved into files (commit e6b132a): [threshold, source, strategies, inputs, model] or the error
BEFORE = json.loads((ROOT / "tests" / "data" / "lrmm_decisions_before.json").read_text())
#: the shipped models with a decision, and the two that also carry the old copy inside the file
DECIDED = {"dubins4d_act", "quadrotor_cmd_act", "dubins3d_maze", "cartpole_guarded", "inverted_pendulum_guarded"}
HOW = {"how": "a test"}


def _resolve(env_id: str, cls, preset, variant):
    model = None if variant == "None" else default_model_path(env_id, variant)
    try:
        g = cls(model=model, settings=None if preset == "None" else preset, env_id=env_id)
    except ValueError:
        return "ValueError"
    return [g.threshold, g.threshold_source, strategy_specs(g.strategies), g.inputs, g.model.path.name]


def test_every_shipped_decision_resolves_as_before_it_moved_into_files():
    classes = {"lrmm": LRMMGuardian, "lrmm-paper": LRMMPaperGuardian}
    assert {k.split("|")[0] for k in BEFORE} == set(SHIPPED)
    changed = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # before: the paper's threshold came with a warning
        for key, before in BEFORE.items():
            env_id, name, preset, variant = key.split("|")
            now = _resolve(env_id, classes[name], preset, variant)
            if variant == "None":  # the guardians as rmm-bench builds them: exactly as before
                assert now == before, key
            elif now != before:
                changed[key] = (before, now)
    # a model file given by path: its decision is the file beside it, whichever env it serves
    # (before: the paper's 0.85 with a warning, unless the model file held one); lrmm-paper reads none
    for key, (before, now) in changed.items():
        env_id, name, preset, variant = key.split("|")
        if name == "lrmm-paper":
            assert now[:3] == [0.85, "paper", []] and before[1] == "stored decision", key
        elif Path(default_model_path(env_id, variant)).stem in DECIDED:
            file = read_decision(decision_path(default_model_path(env_id, variant)))
            assert now[:2] == [file.threshold, "stored decision"] and before[:2] == [0.85, "paper"], key
        else:  # a model without a decision: refused, no longer the paper's threshold in silence
            assert now == "ValueError" and before[:2] == [0.85, "paper"], key
    assert len(changed) == 54


def test_each_decision_has_one_source_a_text_file_beside_its_model():
    names = {p.name.removesuffix(".decision.toml") for p in models_dir().glob("*.decision.toml")}
    assert names == DECIDED
    for name in DECIDED:  # each one's bytes, how it was chosen, and the old copies it replaces
        model = LRMMModel.load(models_dir() / f"{name}.npz")
        d = read_decision(decision_path(model.path))
        assert d.model_sha256 == model.file_sha256 and set(d.chosen_by) == {"how", "command", "seeds", "date"}
        old = model.meta.get("decision")  # the copy older versions read, kept for the file's bytes (run keys)
        if old is not None:
            assert (d.threshold, d.strategies, d.chosen_by["how"]) == (
                old["threshold"],
                ", ".join(old["strategies"]),
                old["chosen_by"],
            )
    assert not hasattr(next(iter(SHIPPED_BY_SYSTEM.values()))["guarded"], "decision")
    # no decision literal in the package's Python: no dict giving a threshold, strategies or how they
    # were chosen as literal values, and only the decision module names the key "decision" (to refuse
    # the old copy, never to read it)
    for path in (ROOT / "guardians").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Dict):
                literal = {
                    k.value
                    for k, v in zip(node.keys, node.values, strict=True)
                    if isinstance(k, ast.Constant) and isinstance(v, (ast.Constant, ast.List, ast.Tuple))
                }
                assert not literal & {"threshold", "strategies", "chosen_by"}, f"{path}:{node.lineno}"
            if isinstance(node, ast.Constant) and node.value == "decision":
                assert path.name in ("decision.py", "model.py"), f"{path}:{node.lineno}"  # model.py: the v1 check


def test_the_decision_files_are_installed_with_the_wheel():
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    patterns = data["rmm_guardians.lrmm.models"]
    for p in models_dir().iterdir():
        if p.suffix in (".npz", ".toml"):
            assert any(fnmatch.fnmatch(p.name, pat) for pat in patterns), p.name


@pytest.mark.parametrize(
    "how",
    [
        "plain",
        'quotes " and """ and \\ backslashes \\n',
        "a\nnew line\tand a tab",
        "unicode: ± µs → 2026",
        "control \x01 and delete \x7f",
        "long " * 200 + "end",
        "spaces  doubled   at   every   break " * 30,
        " leading and trailing ",
    ],
)
def test_a_decision_reads_back_equal_from_its_file(tmp_path, how):
    d = Decision(0.25, "SafestCandidate(), Commit(steps=18)", {"how": how, "date": "2026-12-05"}, "ab" * 32)
    write_decision(tmp_path / "m.decision.toml", d, "m.npz")
    assert read_decision(tmp_path / "m.decision.toml") == d
    text = (tmp_path / "m.decision.toml").read_text()
    assert max(len(line) for line in text.splitlines()) <= 110 and text == to_toml(d, "m.npz")


@settings(max_examples=60, deadline=None)
@given(
    threshold=st.floats(0.0, 1.0),
    how=st.text(min_size=1).filter(str.strip),
    command=st.text(),
)
def test_any_text_and_threshold_round_trip(tmp_path_factory, threshold, how, command):
    d = Decision(threshold, "", {"how": how, "command": command})
    path = tmp_path_factory.mktemp("rt") / "m.decision.toml"
    write_decision(path, d)
    assert read_decision(path) == d


def _file(tmp_path, body: str) -> Path:
    path = tmp_path / "m.decision.toml"
    path.write_text('format = "rmm-lrmm-decision"\nversion = 1\n' + body + '\n[chosen_by]\nhow = "t"\n')
    return path


@pytest.mark.parametrize(
    "body, message",
    [
        ("threshold = 1.5", "threshold must be in [0, 1], got 1.5"),
        ("threshold = -0.1", "threshold must be in [0, 1], got -0.1"),
        ("threshold = nan", "threshold must be in [0, 1], got nan"),
        ("threshold = inf", "threshold must be in [0, 1], got inf"),
        ('threshold = "0.5"', "threshold must be a number in [0, 1], got '0.5'"),
        ("threshold = true", "threshold must be a number in [0, 1], got True"),
        ('threshold = 0.5\nstrategies = "Teleport"', "unknown strategy 'Teleport'"),
        ('threshold = 0.5\nstrategies = "Commit(steps=-1)"', "Commit steps must be an integer >= 0"),
        ('threshold = 0.5\nstrategies = "-Commit"', "a decision names its strategies; +/- edit a stored one"),
        ("threshold = 0.5\ncommit = 18", "unknown key(s) ['commit']"),
        ('threshold = 0.5\nmodel_sha256 = "abc"', "model_sha256 must be 64 lowercase hex digits"),
        ('strategies = ""', "no threshold"),
        ("threshold = ", "not a readable decision file"),
    ],
)
def test_a_bad_decision_file_is_refused_in_one_line_naming_it(tmp_path, body, message):
    path = _file(tmp_path, body)
    with pytest.raises(ValueError) as e:
        read_decision(path)
    assert str(e.value).startswith(f"{path}: ") and message in str(e.value) and "\n" not in str(e.value)


def test_the_format_and_chosen_by_are_checked(tmp_path):
    path = tmp_path / "m.decision.toml"
    path.write_text('format = "other"\nversion = 1\nthreshold = 0.5\n')
    with pytest.raises(ValueError, match="expected format 'rmm-lrmm-decision' version 1, got 'other' version 1"):
        read_decision(path)
    path.write_text('format = "rmm-lrmm-decision"\nversion = 1\nthreshold = 0.5\n[chosen_by]\nwho = "me"\n')
    with pytest.raises(ValueError, match=r"chosen_by has unknown key\(s\) \['who'\]"):
        read_decision(path)
    path.write_text('format = "rmm-lrmm-decision"\nversion = 1\nthreshold = 0.5\n')
    with pytest.raises(ValueError, match="chosen_by.how must say how"):
        read_decision(path)


def _own_copy(tmp_path, name="dubins4d_act") -> Path:
    """A shipped model copied as a model of one's own (the old copy of its decision inside it)."""
    path = tmp_path / "mine.npz"
    shutil.copy(models_dir() / f"{name}.npz", path)
    return path


def test_the_decision_command_writes_beside_the_model_and_refuses_bad_input_in_one_line(tmp_path, capsys):
    p = _own_copy(tmp_path, "cartpole_guarded")
    before = p.read_bytes()
    assert main([str(p), "--threshold", "0.3", "--strategies", "", "--chosen-by", "by hand"]) == 0
    assert capsys.readouterr().out == f"{tmp_path / 'mine.decision.toml'}: decision threshold 0.3, strategies []\n"
    assert p.read_bytes() == before and LRMMGuardian(p, env_id="CartPoleParallel-v0").threshold == 0.3
    for argv, words in [
        (["--threshold", "nan", "--strategies", "", "--chosen-by", "x"], "threshold must be in [0, 1], got nan"),
        (["--threshold", "1.01", "--strategies", "", "--chosen-by", "x"], "threshold must be in [0, 1], got 1.01"),
        (["--threshold", "0.3", "--strategies", "Fly", "--chosen-by", "x"], "unknown strategy 'Fly'"),
        (["--threshold", "0.3", "--strategies", "SafestCandidate", "--chosen-by", "x"], "'candidates'"),
        (["--threshold", "0.3", "--strategies", ""], "give --threshold, --strategies and --chosen-by"),
        (["--from-model"], "stores no decision inside it"),
    ]:
        assert main([str(p), *argv]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err, err
    assert read_decision(decision_path(p)).threshold == 0.3  # every refusal left the file as it was


def test_a_decision_chosen_for_other_model_bytes_is_refused_naming_tune(tmp_path):
    p = _own_copy(tmp_path, "cartpole_guarded")
    set_decision(p, 0.3, "", "a test")
    LRMMGuardian(p, env_id="CartPoleParallel-v0")
    model = LRMMModel.load(p)
    model.meta["note"] = "retrained"  # other bytes under the same name
    model.save(p)
    with pytest.raises(ValueError) as e:
        LRMMGuardian(p, env_id="CartPoleParallel-v0")
    assert str(e.value).startswith(f"lrmm: {decision_path(p)} was chosen for other model bytes (SHA-256 ")
    assert str(e.value).endswith(f"choose again with `rmm-bench tune --env CartPoleParallel-v0 --model {p}`")
    LRMMGuardian(p, env_id="CartPoleParallel-v0", threshold=0.3, strategies="")  # all given: the file is not read


def test_a_decision_left_inside_an_old_model_file_is_named_and_written_out_on_request(tmp_path, capsys):
    p = _own_copy(tmp_path)
    with pytest.raises(ValueError) as e:
        LRMMGuardian(p)
    assert str(e.value) == (
        f"lrmm: {p} holds a decision inside the model file (meta), which is no longer read: write it beside it "
        f"as mine.decision.toml with `python -m rmm_guardians.lrmm.decision {p} --from-model`, or choose one: "
        f"`rmm-bench tune --env Dubins4DGuarded-v0 --model {p}`"
    )
    assert main([str(p), "--from-model"]) == 0
    capsys.readouterr()
    g, shipped = LRMMGuardian(p), LRMMGuardian()
    assert (g.threshold, g.strategies) == (shipped.threshold, shipped.strategies)
    assert read_decision(decision_path(p)).chosen_by["how"] == shipped.model.meta["decision"]["chosen_by"]


def test_a_read_decision_file_keys_the_run_unless_it_is_shipped(tmp_path):
    assert is_shipped(decision_path(default_model_path(variant="act")))
    assert LRMMGuardian().input_files() == {str(default_model_path(variant="act")): LRMMGuardian().model.file_sha256}
    p = _own_copy(tmp_path, "cartpole_guarded")
    set_decision(p, 0.3, "", "a test")
    files = LRMMGuardian(p, env_id="CartPoleParallel-v0").input_files()
    assert set(files) == {str(p), str(decision_path(p))} and not is_shipped(decision_path(p))
    assert files[str(decision_path(p))] == __import__("hashlib").sha256(decision_path(p).read_bytes()).hexdigest()
    # both settings given: the file is not read, so not one of the run's inputs
    assert set(LRMMGuardian(p, env_id="CartPoleParallel-v0", threshold=0.3, strategies="").input_files()) == {str(p)}


def test_the_decision_module_runs_as_a_command_from_a_research_folder(tmp_path):
    p = _own_copy(tmp_path, "cartpole_guarded")
    for pkg in ("benchmarks", "guardians", "tests", "rmm"):
        (tmp_path / pkg).mkdir()
        (tmp_path / pkg / "__init__.py").write_text("raise ImportError('not this one')\n")
    cmd = [sys.executable, "-m", "rmm_guardians.lrmm.decision", "mine.npz", "--threshold", "0.25"]
    ok = subprocess.run([*cmd, "--strategies", "", "--chosen-by", "t"], capture_output=True, text=True, cwd=tmp_path)
    assert ok.returncode == 0, ok.stderr
    assert math.isclose(read_decision(decision_path(p)).threshold, 0.25)
