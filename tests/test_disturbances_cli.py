"""``rmm-bench --disturb`` (issue 52): disturbed runs are stored with their disturbances in the
run's configuration (one canonical form, whatever the order given), replay to ``verified``, pair in
``compare``; bad input is one line, exit 2, nothing written; no ``--disturb``, no trace of it."""

from __future__ import annotations

import json
import sqlite3

import pytest

from rmm_bench.cli import main

RUN = ["--agent", "lrmm,inactive", "--episodes", "4", "--clock", "fixed:1", "--no-progress", "--no-figure"]


def _configs(out) -> list[dict]:
    with sqlite3.connect(out / "results.db") as db:
        return [json.loads(c) for (c,) in db.execute("SELECT config FROM runs")]


def test_a_disturbed_run_is_stored_replayed_and_compared(tmp_path, capsys):
    out = tmp_path / "res"
    assert main([*RUN, "--disturb", "obs-noise.rays=0.2", "--disturb", "dyn-rate=0.1@white", "--out", str(out)]) == 0
    configs = _configs(out)
    assert {json.dumps(c["env_kwargs"]["disturbances"]) for c in configs} == {
        json.dumps(["dyn-rate=0.1@white", "obs-noise.rays=0.2"])
    }
    capsys.readouterr()
    # the same disturbances in another order (and spelled as the env option) are the same runs
    same = ["--env-opt", 'disturbances="dyn-rate=0.1@white; obs-noise.rays=0.2"', "--out", str(out)]
    assert main([*RUN, *same]) == 0
    assert "none left to run" in capsys.readouterr().out and len(_configs(out)) == 2
    assert main(["replay", str(out), "--agent", "lrmm,inactive", "--episode", "0,1,2,3"]) == 0
    assert "verified: 8 episodes" in capsys.readouterr().out
    assert main(["compare", str(out)]) == 0
    assert "| inactive | lrmm | collision | 4 |" in capsys.readouterr().out.replace(
        "lrmm | inactive", "inactive | lrmm"
    )


def test_without_disturb_the_configuration_has_no_trace_of_it(tmp_path):
    out = tmp_path / "plain"
    assert main([*RUN, "--agent", "inactive", "--out", str(out)]) == 0
    assert all("disturbances" not in c["env_kwargs"] for c in _configs(out))


def test_a_users_simulator_takes_sensor_and_actuation_noise(tmp_path, capsys):
    out = tmp_path / "cart"
    argv = ["--env", "CartPoleParallel-v0", "--agent", "lrmm", "--episodes", "2", "--clock", "fixed:1"]
    assert main([*argv, "--no-progress", "--no-figure", "--disturb", "obs-noise=0.05", "--disturb", "act-noise=0.1",
                 "--out", str(out)]) == 0  # fmt: skip
    assert main(["replay", str(out), "--agent", "lrmm", "--episode", "0,1"]) == 0
    assert "verified: 2 episodes" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--disturb", "obs-noise.lidar=0.1"], ["'lidar'", "rays"]),
        (["--disturb", "obs-noise=-1"], ["-1.0", "negative"]),
        (["--disturb", "ray-dropout=2"], ["[0, 1]"]),
        (["--disturb", "gusts=1"], ["'gusts'", "obs-noise"]),
        (["--disturb", "obs-noise=nan"], ["not finite"]),
        (["--disturb", "obs-noise=0.1", "--env-opt", 'disturbances="act-delay=1"'], ["not both"]),
        (["--env", "Dubins3DMazeParallel-v0", "--disturb", "ray-dropout=0.1"], ["no maximum range"]),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, extra, words):
    out = tmp_path / "bad"
    assert main([*RUN, *extra, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and all(w in err for w in words), err
    assert not out.exists()


def test_compare_pairs_runs_only_under_the_same_disturbances(tmp_path, capsys):
    """An undisturbed and a disturbed run of one world start alike (one starts table) but are not
    the same condition: compare keeps them in groups of their own."""
    out = tmp_path / "mixed"
    assert main([*RUN, "--out", str(out)]) == 0
    assert main([*RUN, "--disturb", "act-noise=0.3", "--out", str(out)]) == 0
    capsys.readouterr()
    assert main(["compare", str(out)]) == 0
    text = capsys.readouterr().out
    assert text.count("## Dubins4DParallel-v0 seed 0 clock fixed:1") == 2 and "disturbances act-noise=0.3" in text
    with sqlite3.connect(out / "results.db") as db:
        assert db.execute("SELECT COUNT(DISTINCT world_key) FROM starts").fetchone()[0] == 1
