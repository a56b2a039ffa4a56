"""An episode's replay verdict in each way it can differ: the clock's sums compared when the clock
is reproduced (a fixed clock, or a wall-clock run from its trace), a trace that runs out or is
left unread, and an episode that raised, its last lines shown (tests/test_replay.py replays real
runs end to end; tests/test_replay_compare.py compares rows by hand)."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.store import decode_laps, encode_laps
from rmm_envs.clocks import TraceExhausted

ROOT = Path(__file__).resolve().parents[1]
FAST = ["--workers", "1", "--no-progress", "--no-figure"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    base = tmp_path_factory.mktemp("verdicts")
    for name, clock in (("fixed", "fixed:1"), ("wall", "wall")):
        argv = ["--agent", "random", "--episodes", "2", "--clock", clock, "--out", str(base / name)]
        assert main([*argv, *FAST]) == 0
    return base


def _edited(runs: Path, name: str, dest: Path, *sql) -> tuple[Path, str]:
    shutil.copytree(runs / name, dest)
    con = sqlite3.connect(dest / "results.db")
    try:
        (key,) = con.execute("SELECT run_key FROM runs").fetchone()
        for s in sql:
            con.execute(s[0], tuple(key if v == "KEY" else v for v in s[1]))
        con.commit()
    finally:
        con.close()
    return dest, key


def _replay(capsys, *argv) -> tuple[int, list[str]]:
    capsys.readouterr()
    code = main(["replay", *map(str, argv), "--no-progress"])
    return code, capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("name", ["fixed", "wall"])
def test_the_clocks_sums_are_results_when_the_clock_is_reproduced(runs, tmp_path, capsys, name):
    """Under a fixed clock, and under the wall clock replayed from the stored trace, the agent time
    the clock summed is the episode's own: an edited compute_time differs."""
    copy, _ = _edited(runs, name, tmp_path / "c", ("UPDATE episodes SET compute_time = 9.0 WHERE episode = 1", ()))
    code, lines = _replay(capsys, copy, "--agent", "random", "--episode", "1")
    assert code == 1 and lines[0].startswith("episode 1: differs in compute_time: stored 9.0, replayed ")
    code, lines = _replay(capsys, runs / name, "--agent", "random", "--episode", "1")
    assert code == 0 and lines == ["episode 1: verified"]


def test_a_trace_that_runs_out_is_named(runs, tmp_path, capsys):
    sql = (
        "UPDATE clock_traces SET n = 2, laps = ? WHERE run_key = ? AND episode = 0",
        (encode_laps([0.5, 0.5]), "KEY"),
    )
    copy, key = _edited(runs, "wall", tmp_path / "short", sql)
    code, lines = _replay(capsys, copy, "--agent", "random", "--episode", "0")
    assert code == 1
    assert lines[0].startswith(f"episode 0: differs: {TraceExhausted.__name__}: ")
    assert f"episode 0 of random's run {key}" in lines[0] and "cannot be verified" in lines[0]


def test_a_trace_left_partly_unread_is_a_difference(runs, tmp_path, capsys):
    con = sqlite3.connect(runs / "wall" / "results.db")
    key, codec, n, blob = con.execute("SELECT run_key, codec, n, laps FROM clock_traces WHERE episode = 0").fetchone()
    con.close()
    laps = decode_laps(blob, n, codec) + [0.01] * 5
    sql = (
        "UPDATE clock_traces SET n = ?, laps = ? WHERE run_key = ? AND episode = 0",
        (len(laps), encode_laps(laps), "KEY"),
    )
    copy, _ = _edited(runs, "wall", tmp_path / "long", sql)
    code, lines = _replay(capsys, copy, "--agent", "random", "--episode", "0")
    assert code == 1
    assert lines[0].startswith(f"episode 0: differs in the clock trace: the replay read {n} of its {n + 5} laps ")


def test_an_episode_that_raised_shows_the_last_lines_of_its_error(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "boom"
    argv = ["--agent", "tests.bench_helpers:Boom", "--clock", "fixed:1", "--episodes", "1", "--out", str(out), *FAST]
    assert main(argv) == 1
    con = sqlite3.connect(out / "results.db")
    (error,) = con.execute("SELECT error FROM episodes WHERE episode = 0").fetchone()
    con.close()
    last = [line.strip() for line in error.splitlines()[-3:] if line.strip()]
    assert len(error.splitlines()) > 3 and last[-1].endswith("guardian exploded")
    code, lines = _replay(capsys, out, "--agent", "tests.bench_helpers:Boom", "--episode", "0", "--allow-errors")
    assert code == 0 and lines == ["episode 0: verified; the replay raised: " + " | ".join(last)]
