"""``--shard K/N`` and ``rmm-bench merge``: shares of one run on several machines joined into the
database one machine would have written, every overlap checked, conflicts refused."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3

import pytest

from rmm_bench.cli import main
from rmm_bench.config import parse_shard, shard_episodes
from rmm_bench.store import ResultsStore

EPISODES = 24
RUN = ["--agent", "lrmm,cbf", "--episodes", str(EPISODES), "--clock", "fixed:1", "--workers", "1", "--no-progress"]
#: measured times: the only columns allowed to differ between machines
TIMING = {"decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time", "finished"}


@pytest.fixture(scope="module")
def parts(tmp_path_factory):
    root = tmp_path_factory.mktemp("merge")
    for k in (1, 2):
        assert main([*RUN, "--shard", f"{k}/2", "--out", str(root / f"part{k}")]) == 0
    assert main([*RUN, "--out", str(root / "one")]) == 0
    return root


def _rows(db):
    with sqlite3.connect(db) as con:
        cur = con.execute("SELECT * FROM episodes ORDER BY run_key, episode")
        names = [d[0] for d in cur.description]
        return [{k: v for k, v in zip(names, r, strict=True) if k not in TIMING} for r in cur.fetchall()]


def _digest(folder):
    """Every file's SHA-256 but SQLite's -wal/-shm companions (a read-only reader of a WAL database
    may create them empty; the database file itself must not change)."""
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.iterdir())
        if p.is_file() and not p.name.endswith(("-wal", "-shm"))
    }


def test_shards_are_balanced_and_cover_every_episode_once():
    assert shard_episodes(7, (1, 3)) == [0, 3, 6] and shard_episodes(7, (3, 3)) == [2, 5]
    for n in range(1, 6):
        shares = [shard_episodes(23, (k, n)) for k in range(1, n + 1)]
        assert sorted(sum(shares, [])) == list(range(23))
        assert max(map(len, shares)) - min(map(len, shares)) <= 1


@pytest.mark.parametrize("spec", ["3/2", "0/0", "1/0", "0/2", "a/b", "2", "", "1/2/3", "-1/2"])
def test_a_bad_shard_spec_is_one_line_and_exit_2(spec, capsys):
    with pytest.raises(ValueError, match="--shard"):
        parse_shard(spec)
    assert main(["--agent", "lrmm", "--episodes", "4", f"--shard={spec}"]) == 2
    err = capsys.readouterr().err
    assert "--shard" in err and err.count("\n") == 1


def test_a_shard_runs_its_share_and_says_so(parts):
    with sqlite3.connect(parts / "part2" / "results.db") as con:
        eps = sorted({e for (e,) in con.execute("SELECT episode FROM episodes")})
    assert eps == list(range(1, EPISODES, 2))
    text = (parts / "part2" / "table_I.md").read_text()
    assert "| lrmm |" in text
    main(["report", str(parts / "part2")])


def test_two_shards_merged_equal_one_run(parts, tmp_path, capsys):
    before = {k: _digest(parts / f"part{k}") for k in (1, 2)}
    out = tmp_path / "merged"
    assert main(["merge", str(parts / "part1"), str(parts / "part2"), "--out", str(out)]) == 0
    assert "merged 2 parts" in capsys.readouterr().out
    assert {k: _digest(parts / f"part{k}") for k in (1, 2)} == before  # the inputs are untouched
    assert _rows(out / "results.db") == _rows(parts / "one" / "results.db")  # bit for bit but the timings
    capsys.readouterr()
    assert main(["report", str(out)]) == 0
    merged = capsys.readouterr().out
    assert main(["report", str(parts / "one")]) == 0
    single = capsys.readouterr().out

    def table(text, where):  # the measured decision time is a timing column
        lines = [ln.replace(str(where), "DIR") for ln in text.splitlines()]
        return [ln.split("|")[:6] + ln.split("|")[7:] if ln.startswith("|") else ln for ln in lines]

    assert table(merged, out) == table(single, parts / "one")
    assert "INCOMPLETE" not in merged
    store = ResultsStore(out / "results.db", read_only=True)
    try:
        parts_rows = store.db.execute("SELECT source, shard, episodes, host FROM parts ORDER BY part").fetchall()
    finally:
        store.close()
    assert [(r[1], r[2]) for r in parts_rows] == [("1/2", EPISODES), ("2/2", EPISODES)]
    assert all(r[3] for r in parts_rows)


def test_overlapping_parts_are_checked_and_kept_once(parts, tmp_path, capsys):
    out = tmp_path / "merged"
    assert main(["merge", str(parts / "one"), str(parts / "part1"), "--out", str(out)]) == 0
    assert f"{EPISODES} stored in more than one part" in capsys.readouterr().out
    assert _rows(out / "results.db") == _rows(parts / "one" / "results.db")


@pytest.mark.parametrize(("column", "value"), [("steps", 1), ("outcome", "'timeout'"), ("final_speed", 0.123)])
def test_an_edited_row_makes_merge_refuse_naming_episode_and_column(parts, tmp_path, capsys, column, value):
    edited = tmp_path / "edited"
    shutil.copytree(parts / "part1", edited)
    with sqlite3.connect(edited / "results.db") as con:
        con.execute(f"UPDATE episodes SET {column} = {value} WHERE agent = 'cbf' AND episode = 4")
    out = tmp_path / "merged"
    assert main(["merge", str(parts / "one"), str(edited), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "episode 4 of cbf" in err and f"differs in {column}" in err and err.count("\n") == 1
    assert not (out / "results.db").exists() and not list(out.glob(".results.db*"))


def test_timing_columns_and_timing_stats_never_conflict(parts, tmp_path):
    edited = tmp_path / "edited"
    shutil.copytree(parts / "part1", edited)
    with sqlite3.connect(edited / "results.db") as con:
        con.execute("UPDATE episodes SET decision_mean = 9.0, wall_time = 9.0 WHERE episode = 0")
    assert main(["merge", str(parts / "one"), str(edited), "--out", str(tmp_path / "m")]) == 0


def test_a_wall_clock_overlap_must_be_identical(tmp_path, capsys):
    run = ["--agent", "inactive", "--episodes", "4", "--workers", "1", "--no-progress", "--clock", "wall"]
    assert main([*run, "--out", str(tmp_path / "a")]) == 0
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    with sqlite3.connect(tmp_path / "b" / "results.db") as con:
        con.execute("UPDATE episodes SET wall_time = wall_time + 1 WHERE episode = 2")
    assert main(["merge", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert "episode 2 of inactive" in err and "wall_time" in err and "wall-clock" in err
    # without an overlap, wall-clock parts merge
    assert main([*run, "--shard", "1/2", "--out", str(tmp_path / "s1")]) == 0
    assert main([*run, "--shard", "2/2", "--out", str(tmp_path / "s2")]) == 0
    assert main(["merge", str(tmp_path / "s1"), str(tmp_path / "s2"), "--out", str(tmp_path / "m2")]) == 0


def test_a_crash_leaves_no_half_merged_database(parts, tmp_path, monkeypatch):
    import rmm_bench.merge as merge_module
    import rmm_bench.outputs as outputs

    def crash(*_):
        raise KeyboardInterrupt

    monkeypatch.setattr(outputs.os, "link", crash)  # Ctrl-C just as the merged file is moved into place
    out = tmp_path / "merged"
    with pytest.raises(KeyboardInterrupt):
        merge_module.merge(out, [parts / "part1", parts / "part2"])
    assert list(out.iterdir()) == []


def test_another_configuration_under_one_name_is_refused(parts, tmp_path, capsys):
    other = tmp_path / "other"
    assert main(["--agent", "cbf", "--agent-opt", "cbf.inflation=1.2", "--episodes", "4", "--clock", "fixed:1",
                 "--workers", "1", "--no-progress", "--out", str(other)]) == 0  # fmt: skip
    capsys.readouterr()
    assert main(["merge", str(parts / "part1"), str(other), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert "agent cbf" in err and "agent_kwargs" in err and not (tmp_path / "m" / "results.db").exists()


def test_runs_of_another_seed_are_refused(parts, tmp_path, capsys):
    assert main([*RUN[:-5], "--episodes", "4", "--clock", "fixed:1", "--seed", "3", "--workers", "1", "--no-progress",
                 "--out", str(tmp_path / "s3")]) == 0  # fmt: skip
    assert main(["merge", str(parts / "part1"), str(tmp_path / "s3"), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert "another configuration" in err and "seed" in err


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["merge", "{tmp}/missing", "--out", "{tmp}/m"], "does not exist"),
        (["merge", "{tmp}", "--out", "{tmp}/m"], "holds no results.db"),
        (["merge", "{part1}", "--out", "{part1}"], "is also an input"),
        (["merge", "{part1}", "{part1}", "--out", "{tmp}/m"], "named twice"),
        (["merge", "{part1}", "--out", "{one}"], "exists already"),
        (
            ["merge", "{tmp}/m", "{part1}"],
            "merge: no --out; name the new results directory with --out DIR (rmm-bench merge DIR [DIR ...] "
            "--out DIR): the first directory is an input",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(parts, tmp_path, capsys, args, expected):
    fill = {"tmp": tmp_path, "part1": parts / "part1", "one": parts / "one"}
    assert main([a.format(**fill) for a in args]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1


def test_a_newer_schema_is_refused(parts, tmp_path, capsys):
    copy = tmp_path / "p"
    shutil.copytree(parts / "part1", copy)
    with sqlite3.connect(copy / "results.db") as con:
        con.execute("PRAGMA user_version = 77")
    assert main(["merge", str(copy), str(parts / "part2"), "--out", str(tmp_path / "m")]) == 2
    assert "schema version 77" in capsys.readouterr().err
