"""The results store's schema version (``PRAGMA user_version``) and its migrations
(``benchmarks/bench/store.py``): a legacy database is migrated when opened for writing, read as it
is when opened read-only (its bytes untouched), and a database of a newer schema is refused."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.config import EpisodeResult
from rmm_bench.store import (
    MIGRATIONS,
    SCHEMA_VERSION,
    ResultsDatabaseError,
    ResultsStore,
    decode_laps,
    encode_laps,
)

DATA = Path(__file__).parent / "data"


def _legacy(tmp_path) -> Path:
    path = tmp_path / "results.db"
    shutil.copy(DATA / "bench_results_v0.db", path)  # never modify tests/data
    return path


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _columns(path: Path, table: str) -> list[str]:
    con = sqlite3.connect(path)
    try:
        return [r[1] for r in con.execute(f"PRAGMA table_info({table})")]
    finally:
        con.close()


def _version(path: Path) -> int:
    con = sqlite3.connect(path)
    try:
        return con.execute("PRAGMA user_version").fetchone()[0]
    finally:
        con.close()


def test_schema_version_counts_the_migrations():
    assert SCHEMA_VERSION == len(MIGRATIONS) == 4


def test_a_new_database_is_created_at_the_newest_version(tmp_path):
    store = ResultsStore(tmp_path / "results.db")
    assert store.version == 0 and store.has_traces()
    store.close()
    assert _version(tmp_path / "results.db") == SCHEMA_VERSION
    again = ResultsStore(tmp_path / "results.db")
    assert again.version == SCHEMA_VERSION
    again.close()


def test_legacy_database_is_read_as_it_is_when_opened_read_only(tmp_path):
    path = _legacy(tmp_path)
    before = _digest(path)
    store = ResultsStore(path, read_only=True)
    try:
        assert store.version == 0 and not store.has_traces()
        run = store.runs_of("inactive")[0]
        rows = store.episodes(run["run_key"])
        assert [r["episode"] for r in rows] == [0, 1, 2]
        assert "cost" not in rows[0]  # the legacy layout, not migrated
        assert store.clock_trace(run["run_key"], 0) is None
        with pytest.raises(ResultsDatabaseError, match="opened read-only"):
            store.ensure_run("k", "a", {}, {})
    finally:
        store.close()
    assert _digest(path) == before
    assert "cost" not in _columns(path, "episodes")


def test_legacy_database_is_migrated_when_opened_for_writing(tmp_path):
    path = _legacy(tmp_path)
    con = sqlite3.connect(path)
    stored = con.execute("SELECT * FROM episodes ORDER BY run_key, episode").fetchall()
    con.close()
    store = ResultsStore(path)
    try:
        assert store.version == 0 and store.has_traces()
        key = store.runs_of("inactive")[0]["run_key"]
        assert [r["episode"] for r in store.episodes(key)] == [0, 1, 2]
        assert store.episodes(key)[0]["cost"] is None
    finally:
        store.close()
    assert _version(path) == SCHEMA_VERSION
    assert "cost" in _columns(path, "episodes") and "n" in _columns(path, "clock_traces")
    con = sqlite3.connect(path)
    kept = con.execute("SELECT * FROM episodes ORDER BY run_key, episode")
    assert [row[: len(stored[0])] for row in kept.fetchall()] == stored  # every stored value kept
    con.close()


def test_an_older_unversioned_layout_gets_its_probed_columns(tmp_path):
    """A database from before error kinds and invocation bookkeeping: migration 1 adds them."""
    path = tmp_path / "results.db"
    con = sqlite3.connect(path)
    con.executescript("""
        CREATE TABLE runs (run_key TEXT PRIMARY KEY, agent TEXT NOT NULL, created REAL, config TEXT NOT NULL,
            provenance TEXT NOT NULL);
        CREATE TABLE episodes (run_key TEXT NOT NULL, episode INTEGER NOT NULL, agent TEXT NOT NULL,
            seed INTEGER NOT NULL, outcome TEXT NOT NULL, error TEXT, PRIMARY KEY (run_key, episode));
        CREATE TABLE invocations (id INTEGER PRIMARY KEY AUTOINCREMENT, created REAL, kind TEXT, args TEXT,
            run_keys TEXT, episodes INTEGER, status TEXT);
        INSERT INTO episodes VALUES ('k', 0, 'a', 1, 'error', 'EpisodeTimeout: over');
        INSERT INTO episodes VALUES ('k', 1, 'a', 2, 'error', 'RuntimeError: boom');
        INSERT INTO invocations (kind, status) VALUES ('run', 'done');
    """)
    con.commit()
    con.close()
    ResultsStore(path).close()
    con = sqlite3.connect(path)
    assert con.execute("SELECT error_kind FROM episodes ORDER BY episode").fetchall() == [("timeout",), ("guardian",)]
    assert con.execute("SELECT status FROM invocations").fetchall() == [("finished",)]
    con.close()
    assert {"pid", "host", "updated", "message"} <= set(_columns(path, "invocations"))
    assert _version(path) == SCHEMA_VERSION


@pytest.mark.parametrize("read_only", [False, True])
def test_a_newer_schema_is_refused_in_one_line(tmp_path, read_only):
    path = _legacy(tmp_path)
    con = sqlite3.connect(path)
    con.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 5}")
    con.commit()
    con.close()
    before = _digest(path)
    with pytest.raises(ResultsDatabaseError) as e:
        ResultsStore(path, read_only=read_only)
    text = str(e.value)
    assert "\n" not in text and e.value.status == 2
    assert str(path) in text and f"schema version {SCHEMA_VERSION + 5}" in text
    assert f"versions up to {SCHEMA_VERSION}" in text
    assert _digest(path) == before  # nothing written (no WAL switch, no migration)


def test_read_only_open_of_a_missing_file_names_it(tmp_path):
    with pytest.raises(ResultsDatabaseError, match="does not exist"):
        ResultsStore(tmp_path / "nope.db", read_only=True)
    assert not (tmp_path / "nope.db").exists()


def test_a_trace_is_stored_exactly_beside_its_row_and_replaced_with_it(tmp_path):
    laps = [0.0, 1e-300, 5e-324, 0.001234567891234, 3.0, 1.0 / 3.0, 2.5e-4]
    assert decode_laps(encode_laps(laps), len(laps)) == laps
    store = ResultsStore(tmp_path / "results.db")
    try:
        row = EpisodeResult(run_key="k", episode=0, agent="a", seed=1, outcome="goal", steps=7)
        store.add_episode(row, clock_trace=laps)
        assert store.clock_trace("k", 0) == laps
        store.add_episode(row.replace(outcome="collision"), clock_trace=[9.0])  # a result is never replaced
        assert store.clock_trace("k", 0) == laps and store.episodes("k")[0]["outcome"] == "goal"
        err = EpisodeResult(run_key="k", episode=1, agent="a", seed=2, outcome="error", error_kind="timeout")
        store.add_episode(err, clock_trace=[1.0, 2.0])
        store.add_episode(err.replace(outcome="goal", error_kind=None), clock_trace=[0.5])  # a retried failure
        assert store.clock_trace("k", 1) == [0.5]
        assert store.clock_trace("k", 2) is None
    finally:
        store.close()


def test_a_version_2_database_gets_start_fingerprints_and_the_starts_table(tmp_path):
    """Migration 3 on a database written at version 2: its rows keep every value, ``start`` NULL."""
    path = tmp_path / "results.db"
    store = ResultsStore(path)
    store.add_episode(EpisodeResult(run_key="k", episode=0, agent="a", seed=1, outcome="goal", steps=7))
    store.close()
    con = sqlite3.connect(path)  # back to version 2's layout
    con.execute("DROP TABLE starts")
    con.execute("ALTER TABLE episodes DROP COLUMN start")
    con.execute("PRAGMA user_version = 2")
    con.commit()
    con.close()
    read = ResultsStore(path, read_only=True)
    assert read.starts("w") == {} and "start" not in read.episodes("k")[0]
    read.close()
    store = ResultsStore(path)
    try:
        assert store.version == 2 and store.episodes("k")[0]["start"] is None
        store.add_starts("w", [(0, 11, "abc", True, "brake", 0.5), (1, 12, "def", None, "", 0.0)])
        store.add_starts("w", [(0, 11, "changed", False, "other", 9.0)])  # a stored start is kept
        assert store.starts("w") == {
            0: {"seed": 11, "fingerprint": "abc", "doomed": True, "method": "brake", "seconds": 0.5},
            1: {"seed": 12, "fingerprint": "def", "doomed": None, "method": "", "seconds": 0.0},
        }
        assert store.starts("other") == {}
    finally:
        store.close()
    assert _version(path) == SCHEMA_VERSION


def test_a_version_3_database_gets_the_parts_table(tmp_path):
    """Migration 4 on a database written at version 3: an empty ``parts`` table, rows untouched."""
    path = tmp_path / "results.db"
    store = ResultsStore(path)
    store.add_episode(EpisodeResult(run_key="k", episode=0, agent="a", seed=1, outcome="goal", steps=7, start="s"))
    store.close()
    con = sqlite3.connect(path)
    con.execute("DROP TABLE parts")
    con.execute("PRAGMA user_version = 3")
    con.commit()
    con.close()
    read = ResultsStore(path, read_only=True)  # read as it is: no parts table
    assert not read._table_exists("parts") and read.episodes("k")[0]["start"] == "s"
    read.close()
    store = ResultsStore(path)
    try:
        assert store.version == 3 and store._table_exists("parts")
        assert store.db.execute("SELECT COUNT(*) FROM parts").fetchone()[0] == 0
        assert store.episodes("k")[0]["steps"] == 7
    finally:
        store.close()
    assert _version(path) == SCHEMA_VERSION
