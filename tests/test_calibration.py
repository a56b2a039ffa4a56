"""``rmm-bench calibrate`` (rmm_bench.calibration): the reliability table and error by hand, the Brier
scores of a small real run, a model of one's own, and bad input in one line."""

from __future__ import annotations

import numpy as np
import pytest

from rmm_bench.calibration import CALIBRATED, calibrate, reliability
from rmm_bench.cli import main as bench
from rmm_guardians.lrmm.model import default_model_path


def test_reliability_by_hand():
    pred = np.array([0.05, 0.05, 0.35, 0.95, 1.0])
    label = np.array([0.0, 0.1, 0.5, 1.0, 0.9])
    rows, ece = reliability(pred, label)
    assert [r["bin"] for r in rows] == ["0.0-0.1", "0.3-0.4", "0.9-1.0"]  # a prediction of 1.0 is in the last bin
    assert [r["n"] for r in rows] == [2, 1, 2]
    assert rows[0]["mean_pred"] == pytest.approx(0.05) and rows[0]["mean_label"] == pytest.approx(0.05)
    assert rows[2]["mean_pred"] == pytest.approx(0.975) and rows[2]["mean_label"] == pytest.approx(0.95)
    # |0.05 - 0.05| * 2/5 + |0.35 - 0.5| * 1/5 + |0.975 - 0.95| * 2/5
    assert ece == pytest.approx(0.15 / 5 + 0.025 * 2 / 5)


def test_a_calibrated_map_has_no_error():
    rng = np.random.default_rng(0)
    pred = rng.uniform(0, 1, 1000)
    rows, ece = reliability(pred, pred)
    assert ece == pytest.approx(0.0, abs=1e-12) and sum(r["n"] for r in rows) == 1000


def test_the_shipped_dubins4d_model_on_fresh_worlds(tmp_path, monkeypatch):
    """A small real run: fresh labels of new worlds, the shipped model's Brier score well under
    the best constant's."""
    monkeypatch.setitem(CALIBRATED["Dubins4D"], "size", ["--configs", "4", "--samples-per-config", "32"])
    r = calibrate("Dubins4D", 2026, 1, tmp_path)
    assert r["labels"] == 128 and r["worlds"] == 4
    assert 0 <= r["brier"] < 0.5 * r["brier_constant"] and r["skill"] > 0.5
    assert sum(b["n"] for b in r["bins"]) == 128
    again = calibrate("Dubins4D", 2026, 1, tmp_path / "again")
    assert again["brier"] == r["brier"] and again["dataset_sha256"] == r["dataset_sha256"]  # the same bits


def test_a_model_of_ones_own_on_fresh_worlds_of_its_env(tmp_path, capsys):
    own = tmp_path / "mine.npz"
    own.write_bytes(default_model_path("CartPoleParallel-v0", variant="act").read_bytes())
    argv = ["calibrate", "--env", "CartPoleGuarded-v0", "--model", str(own), "--configs", "2"]
    assert bench([*argv, "--samples-per-config", "16", "--workers", "1", "--out", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "| system | model | labels (worlds) |" in out and "| mine | `mine.npz` | 32 (2) |" in out
    assert (tmp_path / "out" / "calibration.json").exists()


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--systems", "boat"], "--systems 'boat': unknown ['boat']"),
        (["--systems", ","], "unknown none given"),
        (["--world-seed", "1"], "the shipped models were trained on seeds 0 and 1"),
        (["--model", "x.npz"], "--env and --model go together"),
        (["--env", "CartPoleGuarded-v0", "--model", "none.npz"], "none.npz does not exist"),
        (
            [
                "--env",
                "CartPoleGuarded-v0",
                "--model",
                str(default_model_path("CartPoleParallel-v0", "act")),
                "--world-seed",
                "1",
            ],
            "was trained on worlds of that seed",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, expected):
    assert bench(["calibrate", *argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rmm-bench calibrate: error: ") and err.count("\n") == 1 and expected in err, err


def test_a_used_output_folder_is_refused(tmp_path, capsys):
    (tmp_path / "old.txt").write_text("a user's file")
    assert bench(["calibrate", "--out", str(tmp_path)]) == 2
    assert "is not empty" in capsys.readouterr().err
    assert (tmp_path / "old.txt").read_text() == "a user's file"


def test_the_clone_shim_is_the_installed_command():
    from benchmarks import calibration

    assert calibration.calibrate is calibrate and calibration.CALIBRATED is CALIBRATED
