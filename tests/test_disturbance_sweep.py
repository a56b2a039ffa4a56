"""``rmm-bench sweep --disturb KIND=L0,L1,...`` (issue 52): every agent at level 0 (the undisturbed
run itself) and at each level, on the same episodes, the paired change against level 0, a table,
a csv, a figure and a section of the results page; bad input one line, exit 2."""

from __future__ import annotations

import csv
import json
import sqlite3

import pytest

from rmm_bench.cli import main
from rmm_bench.disturb_sweep import Swept, split_swept

SWEEP = ["sweep", "--agent", "inactive,lrmm", "--episodes", "4", "--no-progress"]


def test_the_swept_item_is_the_one_with_several_levels():
    rest, swept = split_swept(["--agent", "lrmm", "--disturb", "act-delay=1", "--disturb=obs-noise.rays=0,0.5,2@white"])
    assert rest == ["--agent", "lrmm", "--disturb", "act-delay=1"]
    assert swept == Swept("obs-noise.rays", (0.0, 0.5, 2.0), "white")
    assert swept.at(0) is None and swept.at(0.5) == "obs-noise.rays=0.5"  # white is the kind's default shape
    assert split_swept(["--disturb", "dyn-rate=0.1"]) == (["--disturb", "dyn-rate=0.1"], None)


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--disturb", "obs-noise=0.1,0.2", "--disturb", "act-noise=0.1,0.2"], ["one disturbance at a time"]),
        (["--disturb", "obs-noise=0.1,-1"], ["-1.0", "negative"]),
        (["--disturb", "ray-dropout=0.5,1.5"], ["[0, 1]"]),
    ],
)
def test_a_bad_sweep_is_refused(argv, words):
    with pytest.raises(ValueError) as e:
        split_swept(argv)
    assert all(w in str(e.value) for w in words)


def test_a_sweep_pairs_every_level_with_the_undisturbed_run(tmp_path, capsys):
    out = tmp_path / "sweep"
    assert main([*SWEEP, "--disturb", "obs-noise.rays=0.5,2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    rows = list(csv.DictReader(open(out / "disturbance_sweep.csv")))
    assert [(r["agent"], float(r["level"])) for r in rows] == [
        ("inactive", 0.0), ("inactive", 0.5), ("inactive", 2.0), ("lrmm", 0.0), ("lrmm", 0.5), ("lrmm", 2.0),
    ]  # fmt: skip
    inactive = [r for r in rows if r["agent"] == "inactive"]
    assert len({r["collision"] for r in inactive}) == 1  # the driver alone reads no rays: the same episodes
    assert all(float(r["collision_diff"]) == 0.0 and float(r["p_value"]) == 1.0 for r in inactive)
    assert all(int(r["paired"]) == 4 for r in rows)
    assert "| inactive | 0.5 |" in printed and (out / "disturbance_sweep.png").stat().st_size > 1000
    with sqlite3.connect(out / "results.db") as db:
        configs = [json.loads(c) for (c,) in db.execute("SELECT config FROM runs WHERE agent = 'inactive'")]
    assert sorted(str(c["env_kwargs"].get("disturbances")) for c in configs) == sorted(
        ["None", "['obs-noise.rays=0.5']", "['obs-noise.rays=2.0']"]
    )
    # level 0 is the plain run: the same command without --disturb reuses its episodes
    assert (
        main(["--agent", "inactive", "--episodes", "4", "--clock", "fixed:1", "--out", str(out), "--no-progress"]) == 0
    )
    assert "none left to run" in capsys.readouterr().out
    # the page of the directory leads its robustness section with the figure and the table
    assert main(["report", str(out), "--html", str(out / "page.html")]) == 0
    page = (out / "page.html").read_text()
    assert "Robustness: who degrades least" in page and "data:image/png;base64" in page and "<td>inactive</td>" in page


def test_a_disturbance_sweep_runs_at_one_latency(tmp_path, capsys):
    out = tmp_path / "bad"
    assert main([*SWEEP, "--disturb", "obs-noise=0.1,0.2", "--latency", "0,5", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "one latency" in err and not out.exists()
