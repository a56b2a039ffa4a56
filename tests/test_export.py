"""``rmm-bench export``: the stored episodes in schema ``rmm-results/1``, read back with pandas alone."""

from __future__ import annotations

import json
import re
import sqlite3
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from rmm_bench.cli import main
from rmm_bench.export import OUTCOME_CODES, SCHEMA, SCHEMA_NAME
from rmm_bench.store import ResultsStore

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("export") / "run"
    argv = ["--agent", "lrmm,inactive", "--episodes", "8", "--clock", "fixed:1", "--workers", "1", "--out", str(out)]
    assert main([*argv, "--no-progress"]) == 0
    return out


def _stored(run) -> pd.DataFrame:
    with sqlite3.connect(run / "results.db") as db:
        return pd.read_sql_query("SELECT * FROM episodes ORDER BY agent, run_key, episode", db)


@pytest.mark.parametrize("fmt", ["parquet", "csv"])
def test_an_export_reads_back_with_pandas_alone(run, tmp_path, fmt):
    out = tmp_path / f"x.{fmt}"
    assert main(["export", str(run), "--format", fmt, "--table", str(out)]) == 0
    df = pd.read_parquet(out) if fmt == "parquet" else pd.read_csv(out)
    assert list(df.columns) == [name for name, *_ in SCHEMA]
    assert set(df.schema) == {SCHEMA_NAME}
    stored = _stored(run)
    assert len(df) == len(stored) == 16
    for col in ("agent", "episode", "outcome", "steps", "active_steps", "start"):
        assert df[col].tolist() == stored[col].tolist(), col
    for col in ("sim_time", "active_sim_time", "final_speed", "decision_mean"):  # floats exactly, CSV included
        assert df[col].tolist() == stored[col].tolist(), col
    assert df.episode_seed.tolist() == stored.seed.tolist()
    assert set(df.env_id) == {"Dubins4DParallel-v0"} and set(df.clock) == {"fixed:1"}
    assert json.loads(df.env_options.iloc[0])["clock"] == "fixed:1"
    assert set(df.outcome) <= set(OUTCOME_CODES)


def test_the_schema_travels_with_the_file(run, tmp_path):
    out = tmp_path / "x.parquet"
    assert main(["export", str(run), "--table", str(out)]) == 0
    meta = json.loads(pq.read_schema(out).metadata[b"rmm_schema"])
    assert meta["schema"] == SCHEMA_NAME and [c["name"] for c in meta["columns"]] == [n for n, *_ in SCHEMA]
    csv = tmp_path / "x.csv"
    assert main(["export", str(run), "--format", "csv", "--table", str(csv)]) == 0
    side = json.loads((tmp_path / "x.csv.schema.json").read_text())
    assert side == meta


def test_the_docs_list_every_column_in_order():
    text = (ROOT / "docs" / "comparing.md").read_text()
    rows = re.findall(r"^\| `([a-z_]+)` \|", text.split("## The export schema", 1)[1], re.M)
    assert rows == [name for name, *_ in SCHEMA]


def test_doomed_flags_come_from_the_starts_table(run, tmp_path):
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    from rmm_envs.starts import world_key

    store = ResultsStore(copy / "results.db")
    config = store.runs_of("lrmm")[0]["config"]
    key = world_key(config["env_id"], config["env_kwargs"], config["seed"])
    with store.db:
        store.db.execute("UPDATE starts SET doomed = (episode = 3) WHERE world_key = ?", (key,))
        store.db.execute("UPDATE starts SET doomed = NULL WHERE world_key = ? AND episode = 5", (key,))
    store.close()
    from rmm_bench.export import export_frame

    df = export_frame(copy)
    assert df[df.episode == 3].doomed.tolist() == [True, True]
    assert df[df.episode == 5].doomed.isna().all()
    assert not df[~df.episode.isin([3, 5])].doomed.any()


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["export", "{root}/missing"], "does not exist"),
        (["export", "{root}"], "holds no results.db"),
        (["export", "{run}", "--format", "xlsx"], "expected parquet or csv"),
        (["export", "{run}", "--agent", "nope"], "--agent nope: not stored"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(run, tmp_path, capsys, args, expected):
    assert main([a.format(root=tmp_path, run=run) for a in args]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1
