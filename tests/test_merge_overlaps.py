"""``rmm-bench merge``'s overlap check on small runs: which clocks make episodes comparable
column by column, a row without a result replaced by one with it (and its clock trace with it),
conflicts named exactly, overlaps counted (tests/test_merge.py runs the shards of a larger run;
tests/test_seeded_bugs_results.py the starts' doomed flags)."""

from __future__ import annotations

import math
import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.merge import MergeConflict, _difference, _reproducible, merge

FAST = ["--workers", "1", "--no-progress", "--no-figure"]


def _run(out: Path, clock: str) -> Path:
    argv = ["--agent", "random,inactive", "--agent-opt", "random.p_active=0.25", "--episodes", "4", "--clock", clock]
    assert main([*argv, *FAST, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("overlaps")
    _run(root / "fixed", "fixed:1")
    _run(root / "wall", "wall")
    return root


def _copy(runs: Path, name: str, dest: Path, *edits) -> Path:
    shutil.copytree(runs / name, dest)
    con = sqlite3.connect(dest / "results.db")
    try:
        for e in edits:
            con.execute(*e)
        con.commit()
    finally:
        con.close()
    return dest


def _query(db: Path, sql: str, *args) -> list[tuple]:
    con = sqlite3.connect(db)
    try:
        return con.execute(sql, args).fetchall()
    finally:
        con.close()


def _rows(db: Path, agent: str, episode: int) -> list[tuple]:
    return _query(db, "SELECT * FROM episodes WHERE agent = ? AND episode = ?", agent, episode)


LOST = (
    "UPDATE episodes SET outcome = 'error', error_kind = 'lost_worker', error = 'lost' WHERE agent = ? AND episode = ?",
)


def test_which_clocks_give_the_same_episodes_everywhere():
    assert _reproducible({"env_kwargs": {}}) and _reproducible({})  # a blocking env: no clock
    for clock in ("fixed:1", "FIXED:20", " fixed :3", "manual", "replay:x"):
        assert _reproducible({"env_kwargs": {"clock": clock}}), clock
    for clock in ("wall", "Wall", "wall:2", "scaled:2"):
        assert not _reproducible({"env_kwargs": {"clock": clock}}), clock


def test_a_wall_clock_rows_every_column_is_compared():
    kept = {"run_key": "k", "episode": 3, "outcome": "goal", "wall_time": 1.5, "final_speed": math.nan}
    assert _difference(kept, {**kept, "run_key": "other", "episode": 9}, False) is None  # the keys are not columns
    assert _difference(kept, dict(kept), False) is None  # NaN equals NaN here
    assert _difference(kept, {**kept, "wall_time": 1.25}, False) == ("wall_time", 1.5, 1.25)  # timing too
    assert _difference(kept, {**kept, "final_speed": 0.0}, False) == ("final_speed", kept["final_speed"], 0.0)
    assert _difference({**kept, "final_speed": 0.0}, kept, False)[0] == "final_speed"
    missing = {k: v for k, v in kept.items() if k != "outcome"}
    assert _difference(kept, missing, False) == ("outcome", "goal", None)
    # under a fixed clock the timing columns are not compared
    assert _difference(kept, {**kept, "wall_time": 1.25}, True) is None
    assert _difference(kept, {**kept, "outcome": "timeout"}, True) == ("outcome", "goal", "timeout")


@pytest.mark.parametrize("order", ["lost first", "lost second"])
def test_a_lost_episode_takes_the_other_parts_result(runs, tmp_path, order):
    lost = _copy(runs, "fixed", tmp_path / "lost", (*LOST, ("random", 2)))
    good = runs / "fixed"
    parts = [lost, good] if order == "lost first" else [good, lost]
    s = merge(tmp_path / "m", parts, write_tables=False)
    db = tmp_path / "m" / "results.db"
    assert _rows(db, "random", 2) == _rows(good / "results.db", "random", 2)
    assert s.episodes == 8 and s.overlaps == 7  # the lost row is no overlap: it has nothing to compare
    assert _query(db, "SELECT COUNT(*) FROM episodes WHERE outcome = 'error'") == [(0,)]


def test_lost_in_every_part_stays_lost_and_a_guardian_error_is_a_result(runs, tmp_path):
    a = _copy(runs, "fixed", tmp_path / "a", (*LOST, ("random", 2)))
    b = _copy(runs, "fixed", tmp_path / "b", (*LOST, ("random", 2)))
    s = merge(tmp_path / "m", [a, b], write_tables=False)
    assert s.overlaps == 7 and _rows(tmp_path / "m" / "results.db", "random", 2) == _rows(a / "results.db", "random", 2)
    # a guardian's error is the episode's result: a part that disagrees with it is refused
    guardian_error = (
        "UPDATE episodes SET outcome = 'error', error_kind = 'guardian', error = 'boom' WHERE agent = ? AND episode = ?"
    )
    raised = _copy(runs, "fixed", tmp_path / "raised", (guardian_error, ("random", 2)))
    with pytest.raises(MergeConflict, match="episode 2 of random .* differs in outcome"):
        merge(tmp_path / "m2", [raised, runs / "fixed"], write_tables=False)
    with pytest.raises(MergeConflict, match="episode 2 of random .* differs in outcome"):
        merge(tmp_path / "m3", [runs / "fixed", raised], write_tables=False)


def test_a_conflict_names_the_episode_the_column_and_both_parts(runs, tmp_path):
    edited = _copy(
        runs, "fixed", tmp_path / "edited", ("UPDATE episodes SET steps = 7 WHERE agent = 'random' AND episode = 3",)
    )
    sql = "SELECT run_key, steps FROM episodes WHERE agent = 'random' AND episode = 3"
    ((key, steps),) = _query(runs / "fixed" / "results.db", sql)
    with pytest.raises(MergeConflict) as e:
        merge(tmp_path / "m", [runs / "fixed", edited], write_tables=False)
    assert str(e.value) == (
        f"episode 3 of random (run {key}) differs in steps: {steps!r} in {runs / 'fixed'}, 7 in {edited}; nothing was written"
    )
    assert not (tmp_path / "m" / "results.db").exists()


def test_a_wall_clock_overlap_is_compared_in_every_column_and_says_why(runs, tmp_path):
    edited = _copy(
        runs,
        "wall",
        tmp_path / "edited",
        ("UPDATE episodes SET wall_time = 99.0 WHERE agent = 'inactive' AND episode = 1",),
    )
    sql = "SELECT run_key, wall_time FROM episodes WHERE agent = 'inactive' AND episode = 1"
    ((key, wall),) = _query(runs / "wall" / "results.db", sql)
    with pytest.raises(MergeConflict) as e:
        merge(tmp_path / "m", [runs / "wall", edited], write_tables=False)
    assert str(e.value) == (
        f"episode 1 of inactive (run {key}) differs in wall_time: {wall!r} in {runs / 'wall'}, 99.0 in {edited} "
        "(a wall-clock run: its episodes depend on the machine, overlaps must be identical); nothing was written"
    )
    # the same edit of a fixed-clock run's timing column is no conflict
    timed = _copy(
        runs,
        "fixed",
        tmp_path / "timed",
        ("UPDATE episodes SET wall_time = 99.0 WHERE agent = 'inactive' AND episode = 1",),
    )
    assert merge(tmp_path / "m2", [runs / "fixed", timed], write_tables=False).overlaps == 8


def test_a_replaced_rows_clock_trace_comes_with_it(runs, tmp_path):
    """Wall-clock parts: episode 1 of inactive lost in one (its trace garbled), whole in the other:
    the merged database holds the whole row and that part's trace, whichever comes first."""
    (key,) = _query(runs / "wall" / "results.db", "SELECT run_key FROM runs WHERE agent = 'inactive'")[0]
    lost = _copy(
        runs, "wall", tmp_path / "lost",
        (*LOST, ("inactive", 1)),
        ("UPDATE clock_traces SET n = 1, laps = X'00' WHERE run_key = ? AND episode = 1", (key,)),
    )  # fmt: skip
    trace = "SELECT codec, n, laps FROM clock_traces WHERE run_key = ? AND episode = ?"
    whole = _query(runs / "wall" / "results.db", trace, key, 1)
    assert whole and whole != _query(lost / "results.db", trace, key, 1)
    for i, parts in enumerate(([lost, runs / "wall"], [runs / "wall", lost])):
        merge(tmp_path / f"m{i}", parts, write_tables=False)
        db = tmp_path / f"m{i}" / "results.db"
        assert _query(db, trace, key, 1) == whole
        assert _rows(db, "inactive", 1) == _rows(runs / "wall" / "results.db", "inactive", 1)
        assert _query(db, "SELECT COUNT(*) FROM clock_traces") == _query(
            runs / "wall" / "results.db", "SELECT COUNT(*) FROM clock_traces"
        )


def test_a_run_key_with_another_configuration_is_a_damaged_file(runs, tmp_path):
    (key,) = _query(runs / "fixed" / "results.db", "SELECT run_key FROM runs WHERE agent = 'random'")[0]
    damaged = _copy(
        runs, "fixed", tmp_path / "damaged",
        ("UPDATE runs SET config = json_set(config, '$.agent_kwargs.p_active', 0.5) WHERE run_key = ?", (key,)),
    )  # fmt: skip
    with pytest.raises(MergeConflict) as e:
        merge(tmp_path / "m", [runs / "fixed", damaged], write_tables=False)
    assert str(e.value) == f"run {key} has another configuration in {damaged} than in {runs / 'fixed'}"


def test_equal_starts_are_kept_once_from_the_first_part(runs, tmp_path):
    slow = _copy(runs, "fixed", tmp_path / "slow", ("UPDATE starts SET seconds = 42.0",))
    merge(tmp_path / "m", [runs / "fixed", slow], write_tables=False)
    sql = "SELECT world_key, episode, seed, fingerprint, doomed, method, seconds FROM starts ORDER BY episode"
    assert _query(tmp_path / "m" / "results.db", sql) == _query(runs / "fixed" / "results.db", sql)
    merge(tmp_path / "m2", [slow, runs / "fixed"], write_tables=False)
    assert _query(tmp_path / "m2" / "results.db", sql) == _query(slow / "results.db", sql)


def test_a_fixed_clock_runs_clock_sums_are_results(runs, tmp_path):
    """Under a fixed clock the summed laps (compute_time, avg_compute_time) are the same on every
    machine: a part that disagrees is refused; under the wall clock they are timings of it."""
    for col in ("compute_time", "avg_compute_time"):
        edited = _copy(
            runs, "fixed", tmp_path / col, (f"UPDATE episodes SET {col} = 5.0 WHERE agent = 'random' AND episode = 0",)
        )
        with pytest.raises(MergeConflict, match=f"episode 0 of random .* differs in {col}: "):
            merge(tmp_path / f"m-{col}", [runs / "fixed", edited], write_tables=False)


def test_a_trace_without_its_episode_is_left_out(runs, tmp_path):
    """A clock trace whose episode row is gone (a hand-edited or damaged part) is not merged, and
    does not stop the merge."""
    (key,) = _query(runs / "wall" / "results.db", "SELECT run_key FROM runs WHERE agent = 'inactive'")[0]
    edited = _copy(
        runs, "wall", tmp_path / "edited", ("DELETE FROM episodes WHERE run_key = ? AND episode = 3", (key,))
    )
    assert _query(
        edited / "results.db", "SELECT COUNT(*) FROM clock_traces WHERE run_key = ? AND episode = 3", key
    ) == [(1,)]
    s = merge(tmp_path / "m", [edited], write_tables=False)
    db = tmp_path / "m" / "results.db"
    assert s.episodes == 7 and _query(
        db, "SELECT COUNT(*) FROM clock_traces WHERE episode = 3 AND run_key = ?", key
    ) == [(0,)]
    assert _query(db, "SELECT COUNT(*) FROM clock_traces") == [(7,)]
