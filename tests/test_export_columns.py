"""``rmm-bench export``'s table column by column against the stored run: options as sorted JSON,
defaults for what older runs did not store, provenance, doomed flags, a chosen agent, an older
layout of the episodes table; the files' schema (the side file byte for byte, Parquet's pandas
types and no index column); the database never written (tests/test_export.py reads exports back)."""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from rmm_bench.cli import main
from rmm_bench.export import OUTCOME_CODES, SCHEMA, SCHEMA_NAME, export_frame, schema_description, write_export
from rmm_bench.store import ResultsStore
from rmm_envs.starts import world_key

NAMES = [name for name, *_ in SCHEMA]


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export_columns") / "run"
    argv = [
        "--agent",
        "random,inactive",
        "--agent-opt",
        "random.p_active=0.25",
        "--episodes",
        "4",
        "--clock",
        "fixed:1",
    ]
    assert main([*argv, "--workers", "1", "--no-progress", "--no-figure", "--out", str(out)]) == 0
    return out


def _copy(run: Path, dest: Path, *sql) -> Path:
    shutil.copytree(run, dest)
    con = sqlite3.connect(dest / "results.db")
    try:
        for s in sql:
            con.execute(*s) if isinstance(s, tuple) else con.execute(s)
        con.commit()
    finally:
        con.close()
    return dest


def _runs(db: Path) -> dict[str, tuple[dict, dict]]:
    con = sqlite3.connect(db)
    try:
        return {
            a: (json.loads(c), json.loads(p)) for a, c, p in con.execute("SELECT agent, config, provenance FROM runs")
        }
    finally:
        con.close()


def _doomed(db: Path) -> dict[int, bool]:
    (config, _) = next(iter(_runs(db).values()))
    store = ResultsStore(db, read_only=True)
    try:
        starts = store.starts(world_key(config["env_id"], config["env_kwargs"], config["seed"]))
    finally:
        store.close()
    return {e: bool(s["doomed"]) for e, s in starts.items()}


def test_every_run_column_is_the_runs_own(run):
    df = export_frame(run)
    runs = _runs(run / "results.db")
    doomed = _doomed(run / "results.db")
    assert list(df.columns) == NAMES and len(df) == 8
    assert list(df.agent) == ["inactive"] * 4 + ["random"] * 4 and list(df.episode) == [0, 1, 2, 3] * 2
    for r in df.itertuples():
        config, prov = runs[r.agent]
        assert r.schema == SCHEMA_NAME and r.env_id == config["env_id"] and r.run_seed == 0
        assert r.env_options == json.dumps(config["env_kwargs"], sort_keys=True)
        assert r.agent_options == json.dumps(config["agent_kwargs"], sort_keys=True)
        assert r.clock == "fixed:1"
        assert r.package_version == prov["package_version"] and r.package_version
        assert r.git_revision == prov.get("git_revision")
        assert r.doomed == doomed[r.episode]


def test_export_never_writes_the_database(run):
    before = hashlib.sha256((run / "results.db").read_bytes()).hexdigest()
    files = sorted(p.name for p in run.iterdir())
    export_frame(run)
    assert hashlib.sha256((run / "results.db").read_bytes()).hexdigest() == before
    assert sorted(p.name for p in run.iterdir()) == files


def test_options_are_json_with_sorted_keys(run, tmp_path):
    """Options stored in another key order (a hand-edited or third-party database) export sorted."""
    copy = _copy(
        run, tmp_path / "c",
        "UPDATE runs SET config = json_set(config, '$.env_kwargs.a_first', 1, '$.agent_kwargs.a_first', 2)",
    )  # fmt: skip
    df = export_frame(copy)
    assert set(df.env_options) == {'{"a_first": 1, "base_step": 0.1, "clock": "fixed:1", "time_accel": 10.0}'}
    assert set(df[df.agent == "random"].agent_options) == {'{"a_first": 2, "p_active": 0.25}'}


def test_what_an_older_run_did_not_store_has_its_default(run, tmp_path):
    """No env options (so no clock: the wall clock), no agent options, no seed (0): the columns say
    so, and the doomed flags are still found for seed 0."""
    copy = _copy(run, tmp_path / "c", "UPDATE runs SET config = json_remove(config, '$.seed', '$.agent_kwargs')")
    df = export_frame(copy)
    assert set(df.run_seed) == {0} and set(df.agent_options) == {"{}"}
    assert list(df.doomed) == [_doomed(run / "results.db")[e] for e in df.episode]
    bare = _copy(run, tmp_path / "bare", "UPDATE runs SET config = json_remove(config, '$.env_kwargs')")
    df = export_frame(bare)
    assert set(df.env_options) == {"{}"} and set(df.clock) == {"wall"}
    no_clock = _copy(run, tmp_path / "no_clock", "UPDATE runs SET config = json_remove(config, '$.env_kwargs.clock')")
    assert set(export_frame(no_clock).clock) == {"wall"}
    other_seed = _copy(run, tmp_path / "seed7", "UPDATE runs SET config = json_set(config, '$.seed', 7)")
    df = export_frame(other_seed)
    assert set(df.run_seed) == {7} and df.doomed.isna().all()  # the starts of seed 7 were never assessed


def test_a_chosen_agent_alone_and_an_unknown_one_named(run):
    df = export_frame(run, ["random"])
    assert set(df.agent) == {"random"} and list(df.episode) == [0, 1, 2, 3] and list(df.index) == [0, 1, 2, 3]
    with pytest.raises(ValueError) as e:
        export_frame(run, ["random", "nope"])
    assert str(e.value) == f"--agent nope: not stored in {run / 'results.db'} (expected one of: inactive, random)"
    with pytest.raises(ValueError, match=r"^export .*: it does not exist; expected the --out directory"):
        export_frame(run / "missing")


def test_an_older_episodes_table_exports_its_missing_columns_empty(run, tmp_path):
    copy = _copy(
        run, tmp_path / "old", "ALTER TABLE episodes DROP COLUMN cost", "ALTER TABLE episodes DROP COLUMN start"
    )
    df = export_frame(copy)
    assert df.cost.isna().all() and df.start.isna().all() and len(df) == 8
    assert list(df.steps) == list(export_frame(run).steps)


# ---------------------------------------------------------------- the files


def test_the_schema_description_is_the_schema():
    assert schema_description() == {
        "schema": SCHEMA_NAME,
        "columns": [{"name": n, "type": t, "unit": u, "meaning": m} for n, t, u, m in SCHEMA],
        "outcomes": OUTCOME_CODES,
    }


def test_the_csv_side_file_holds_the_schema_as_written(run, tmp_path):
    out = tmp_path / "x.csv"
    assert write_export(export_frame(run), out, "csv") == [out, tmp_path / "x.csv.schema.json"]
    assert (tmp_path / "x.csv.schema.json").read_text() == json.dumps(schema_description(), indent=1) + "\n"
    assert pd.read_csv(out).columns.tolist() == NAMES


def test_a_parquet_file_keeps_the_types_and_no_index(run, tmp_path):
    frame = export_frame(run).iloc[[0, 3, 5]]  # an index that is no range
    out = tmp_path / "x.parquet"
    assert write_export(frame, out, "parquet") == [out]
    schema = pq.read_schema(out)
    assert schema.names == NAMES  # no index column
    assert b"pandas" in schema.metadata and json.loads(schema.metadata[b"rmm_schema"]) == schema_description()
    back = pd.read_parquet(out)
    assert {c: str(t) for c, t in back.dtypes.items()} == {n: t for n, t, _, _ in SCHEMA}
    assert back.reset_index(drop=True).equals(frame.reset_index(drop=True))


def test_an_unknown_format_is_refused(run, tmp_path):
    with pytest.raises(ValueError) as e:
        write_export(export_frame(run), tmp_path / "x.xlsx", "xlsx")
    assert str(e.value) == "--format 'xlsx': expected parquet or csv"
