"""``rmm-bench tune``: a model of one's own gets its lrmm decision chosen on development episodes and
written beside it, where the guardian reads it; the rule by hand; bad input in one line, exit 2."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.tune import RULE, choose
from rmm_guardians.lrmm.decision import decision_path, read_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.model import LRMMModel, default_model_path
from rmm_guardians.lrmm.train import TrainConfig, train

BIN = Path(sysconfig.get_path("scripts"))


def _row(t, collision, success, intervention, spec=""):
    return {
        "threshold": t,
        "strategies": spec,
        "collision_mean": collision,
        "success_mean": success,
        "intervention_mean": intervention,
    }


def test_the_rule_by_hand():
    rows = [_row(0.1, 0.0, 30.0, 60.0), _row(0.2, 0.0, 50.0, 40.0), _row(0.3, 3.0, 70.0, 20.0)]
    assert choose(rows) is rows[1]  # the fewest collisions, then the most goals
    tie = [_row(0.2, 5.0, 50.0, 30.0), _row(0.5, 5.0, 50.0, 20.0), _row(0.7, 5.0, 50.0, 20.0)]
    assert choose(tie) is tie[2]  # then the least time in control, then the higher threshold
    assert choose(rows, max_intervention=25.0) is rows[2]  # only the candidates within the cap
    assert choose(rows, max_intervention=10.0) is None
    assert "lowest collision rate" in RULE


@pytest.fixture(scope="module")
def own_model(small_dataset, tmp_path_factory):
    """A small model of one's own (Dubins4D labels, three epochs): no decision beside it."""
    ds, _ = small_dataset
    folder = tmp_path_factory.mktemp("research")
    for pkg in ("benchmarks", "guardians", "tests", "rmm"):  # a research folder's own packages
        (folder / pkg).mkdir()
        (folder / pkg / "__init__.py").write_text("raise ImportError('a package of the research folder')\n")
    path = train(ds, TrainConfig(epochs=3, seed=1), log=lambda *a: None).save(folder / "mine.npz")
    return path


def test_tune_chooses_on_development_episodes_and_writes_the_decision_the_guardian_reads(own_model):
    folder = own_model.parent
    with pytest.raises(ValueError, match="has no decision"):
        LRMMGuardian(own_model, env_id="Dubins4DParallel-v0")
    argv = ["tune", "--env", "Dubins4DParallel-v0", "--model", "mine.npz", "--thresholds", "0.3,0.9"]
    argv += ["--episodes", "3", "--workers", "1"]
    env = dict(os.environ, MPLBACKEND="Agg")
    done = subprocess.run([str(BIN / "rmm-bench"), *argv], capture_output=True, text=True, cwd=folder, env=env)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert "| threshold | strategies | Success [%] | Collision [%] | Timeout [%] | Intervention [% sim time] |" in out
    assert out.count("| chosen |") == 1 and "| driver alone (inactive) |" in out and f"Rule: {RULE}." in out
    results = folder / "results" / "tune" / "mine"
    assert (results / "tune.md").read_text().splitlines()[2:5] == out.splitlines()[2:5]
    assert (results / "tune.png").stat().st_size > 1000
    d = read_decision(decision_path(own_model))
    chosen = next(line for line in out.splitlines() if line.endswith("| chosen |"))
    assert chosen.startswith(f"| {d.threshold:g} | (core alone) |") and d.threshold in (0.3, 0.9)
    assert d.strategies == "" and d.model_sha256 == LRMMModel.load(own_model).file_sha256
    assert d.chosen_by["command"] == "rmm-bench tune " + " ".join(argv[1:])
    assert d.chosen_by["seeds"] == "rmm-bench --seed 5, 3 episodes of Dubins4DParallel-v0, clock fixed:1"
    assert d.chosen_by["how"].startswith(f"rmm-bench tune's rule: {RULE}; over thresholds 0.3, 0.9 x strategies ''")
    g = LRMMGuardian(own_model, env_id="Dubins4DParallel-v0")
    assert (g.threshold, g.threshold_source, g.strategies) == (d.threshold, "stored decision", ())
    # again: the runs resume, the decision is replaced; with a cap no candidate meets, nothing is written
    before = decision_path(own_model).read_text()
    assert main([*argv[:4], str(own_model), *argv[5:], "--out", str(results), "--dry-run"]) == 0
    assert decision_path(own_model).read_text() == before
    capped = [*argv[:4], str(own_model), "--thresholds", "0", "--episodes", "3", "--workers", "1"]
    capped += ["--max-intervention", "0", "--no-reference", "--out", str(results)]
    assert main(capped) == 1 and decision_path(own_model).read_text() == before


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--thresholds", "0.2,1.5"], "--thresholds must be in [0, 1], got 1.5"),
        (["--thresholds", "nan"], "--thresholds must be in [0, 1], got nan"),
        (["--thresholds", "0.2,low"], "--thresholds must be comma-separated numbers in [0, 1], got 'low'"),
        (["--thresholds", ","], "--thresholds must be comma-separated numbers"),
        (["--strategies", "Teleport"], "unknown strategy 'Teleport'"),
        (["--strategies", "SafestCandidate"], "'candidates'"),  # the model has no head
        (["--strategies=-Commit"], "a candidate names its strategies"),
        (["--max-intervention", "150"], "--max-intervention must be a share of time in [0, 100] %, got 150"),
        (["--episodes", "0"], "--episodes must be >= 1"),
        (["--clock", "wall"], "--clock must be fixed:MS"),
        (["--agent-opt", "lrmm.threshold=0.5"], "tune sets those"),
    ],
)
def test_bad_input_is_one_line_and_exit_2_before_any_run(own_model, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    argv = ["tune", "--env", "Dubins4DParallel-v0", "--model", str(own_model), "--out", str(out), *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("rmm-bench tune: error: ") and err.count("\n") == 1 and message in err, err
    assert not out.exists()


def test_a_missing_or_shipped_model_is_refused_in_one_line(tmp_path, capsys):
    assert main(["tune", "--env", "CartPoleParallel-v0", "--model", str(tmp_path / "none.npz")]) == 2
    assert "does not exist" in capsys.readouterr().err
    shipped = default_model_path("CartPoleParallel-v0", variant="act")
    assert main(["tune", "--env", "CartPoleParallel-v0", "--model", str(shipped), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a model this package ships" in err and "--dry-run" in err


def test_tune_is_a_listed_subcommand():
    done = subprocess.run([sys.executable, "-m", "rmm_bench.cli", "tune", "--help"], capture_output=True, text=True)
    assert done.returncode == 0 and "MODEL.decision.toml" in done.stdout


def test_rows_over_several_models_by_hand():
    from rmm_bench.tune import combine

    a = {**_row(0.3, 10.0, 60.0, 20.0), "timeout_mean": 30.0, "success_std": 1.0, "collision_std": 2.0}
    a.update(timeout_std=3.0, intervention_std=4.0)
    b = {**a, "collision_mean": 20.0, "success_mean": 50.0, "timeout_mean": 30.0, "intervention_mean": 30.0}
    c = {**a, "collision_mean": 30.0, "success_mean": 40.0, "timeout_mean": 30.0, "intervention_mean": 40.0}
    row = combine([a, b, c])
    assert (row["collision_mean"], row["success_mean"], row["timeout_mean"], row["intervention_mean"]) == (
        20.0, 50.0, 30.0, 30.0,
    )  # fmt: skip
    assert (row["collision_std"], row["timeout_std"]) == (10.0, 0.0)  # across the models' means, n - 1
    assert row["collision_each"] == [10.0, 20.0, 30.0]
    one = combine([a])
    assert one["collision_std"] == 2.0 and one["collision_each"] == [10.0]  # one model keeps its own spread


def test_tune_over_several_models_chooses_by_their_mean(own_model, small_dataset):
    folder = own_model.parent
    ds, _ = small_dataset
    other = train(ds, TrainConfig(epochs=3, seed=2), log=lambda *a: None).save(folder / "mine_seed2.npz")
    argv = ["tune", "--env", "Dubins4DParallel-v0", "--model", str(own_model), "--also-models", str(other)]
    argv += ["--thresholds", "0.3,0.9", "--episodes", "3", "--workers", "1", "--no-reference", "--dry-run"]
    argv += ["--out", str(folder / "several")]
    done = subprocess.run([str(BIN / "rmm-bench"), *argv], capture_output=True, text=True, cwd=folder,
                          env=dict(os.environ, MPLBACKEND="Agg"))  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (
        "| Collision per model [%] |" in done.stdout and "mean over 2 models (mine.npz, mine_seed2.npz)" in done.stdout
    )
    assert sorted(p.name for p in (folder / "several").iterdir() if p.is_dir()) == [
        "s0_t0.3", "s0_t0.3_m1", "s0_t0.9", "s0_t0.9_m1",
    ]  # fmt: skip


@pytest.mark.parametrize("twice", ["same", "model"])
def test_a_model_given_twice_is_refused(own_model, tmp_path, capsys, twice):
    also = f"{own_model},{own_model}" if twice == "same" else str(own_model)
    argv = ["tune", "--env", "Dubins4DParallel-v0", "--model", str(own_model), "--also-models", also]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "twice or as --model" in err and not (tmp_path / "o").exists()
