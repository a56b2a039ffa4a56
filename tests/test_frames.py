"""benchmarks.load_results: the results database as a pandas DataFrame."""

from __future__ import annotations

import sqlite3

import pytest

from benchmarks import load_results
from benchmarks.bench.cli import main as bench
from benchmarks.bench.store import ResultsDatabaseError


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("frames")
    assert bench(["--agent", "inactive,cbf", "--episodes", "3", "--workers", "1", "--clock", "fixed:1",
                  "--no-progress", "--out", str(out)]) == 0
    return out


def test_one_row_per_stored_episode_with_every_field(results):
    df = load_results(results)
    con = sqlite3.connect(results / "results.db")
    stored = con.execute("SELECT agent, episode, seed, outcome, steps, final_speed FROM episodes "
                         "ORDER BY agent, episode").fetchall()
    cols = [r[1] for r in con.execute("PRAGMA table_info(episodes)")]
    con.close()
    assert len(df) == len(stored) == 6
    assert set(cols) <= set(df.columns)
    got = list(df[["agent", "episode", "seed", "outcome", "steps", "final_speed"]].itertuples(index=False, name=None))
    assert got == stored  # the same values, bit for bit, in the documented order
    assert [c["agent"] for c in df["config"]] == list(df["agent"])  # each row carries its own run's config
    assert {c["env_kwargs"]["clock"] for c in df["config"]} == {"fixed:1"}


def test_the_database_file_itself_and_expanded_stats(results):
    df = load_results(results / "results.db", expand_stats=True)
    assert "stats.qp_solves" in df.columns  # cbf reports its QP solves
    cbf = df[df.agent == "cbf"]
    assert (cbf["stats.qp_solves"] > 0).all()
    assert df[df.agent == "inactive"]["stats.qp_solves"].isna().all()


def test_bad_paths_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results database"):
        load_results(tmp_path / "nowhere")
    bad = tmp_path / "results.db"
    bad.write_bytes(b"not a database at all" * 100)
    with pytest.raises(ResultsDatabaseError, match="results.db"):
        load_results(tmp_path)
