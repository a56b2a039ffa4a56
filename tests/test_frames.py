"""rmm_bench.load_results: the results database as a pandas DataFrame."""

from __future__ import annotations

import math
import sqlite3

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_bench import load_results, table_i
from rmm_bench.cli import main as bench
from rmm_bench.metrics import aggregate
from rmm_bench.store import ResultsDatabaseError


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("frames")
    assert (
        bench(
            [
                "--agent",
                "inactive,cbf",
                "--episodes",
                "3",
                "--workers",
                "1",
                "--clock",
                "fixed:1",
                "--no-progress",
                "--no-figure",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out


def test_one_row_per_stored_episode_with_every_field(results):
    df = load_results(results)
    con = sqlite3.connect(results / "results.db")
    stored = con.execute(
        "SELECT agent, episode, seed, outcome, steps, final_speed FROM episodes ORDER BY agent, episode"
    ).fetchall()
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
    cbf = df[df.agent == "cbf"]  # a safe nominal control passes without a solve: some episodes need none
    assert (cbf["stats.qp_solves"] >= 0).all() and cbf["stats.qp_solves"].sum() > 0
    assert df[df.agent == "inactive"]["stats.qp_solves"].isna().all()


def test_bad_paths_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no results database"):
        load_results(tmp_path / "nowhere")
    bad = tmp_path / "results.db"
    bad.write_bytes(b"not a database at all" * 100)
    with pytest.raises(ResultsDatabaseError, match="results.db"):
        load_results(tmp_path)


def _reference_row(episodes, batch_size):
    """Table I by hand, in plain Python: the paper's statistics, independent of the pandas code.
    The rates are over every episode with a result, a guardian error counted as a failure."""
    ok = sorted((e for e in episodes if e["outcome"] != "error"), key=lambda e: e["episode"])
    rated = sorted(
        (
            e
            for e in episodes
            if not (e["outcome"] == "error" and e.get("error_kind") in ("timeout", "lost_worker", "input_changed"))
        ),
        key=lambda e: e["episode"],
    )

    def mean_std(x):
        if not x:
            return math.nan, math.nan
        m = sum(x) / len(x)
        return m, math.sqrt(sum((v - m) ** 2 for v in x) / len(x))

    row = {"episodes": len(episodes), "errors": len(episodes) - len(ok)}
    row["compute_ms"], row["compute_ms_std"] = mean_std(
        [e["compute_time"] / e["steps"] * 1e3 for e in ok if e["steps"]]
    )
    for name in ("goal", "collision", "timeout"):
        if 0 < len(rated) <= batch_size:  # one batch: the 95% Wilson half-width over the episodes
            p, n, z = sum(e["outcome"] == name for e in rated) / len(rated), len(rated), 1.959963984540054
            row[name] = 100 * p
            row[f"{name}_std"] = 100 * z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
            continue
        batches = [rated[i : i + batch_size] for i in range(0, len(rated), batch_size)]
        rates = [sum(e["outcome"] == name for e in b) / len(b) for b in batches]
        w = [len(b) for b in batches]
        if not w:
            row[name] = row[f"{name}_std"] = math.nan
            continue
        m = sum(r * n for r, n in zip(rates, w, strict=True)) / sum(w)  # one rate and size per batch
        row[name] = 100 * m
        row[f"{name}_std"] = 100 * math.sqrt(sum(n * (r - m) ** 2 for r, n in zip(rates, w, strict=True)) / sum(w))
    row["intervention"], row["intervention_std"] = (
        100 * v for v in mean_std([e["active_sim_time"] / e["sim_time"] for e in ok])
    )
    return row


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["a", "b"]),
            st.sampled_from(["goal", "collision", "timeout", "error"]),
            st.integers(1, 900),
            st.floats(0.0, 1.0),
            st.floats(0.0, 0.05),
        ),
        min_size=1,
        max_size=150,
    ),
    st.sampled_from([1, 4, 64]),
)
def test_table_i_agrees_with_a_plain_python_reference(rows, batch_size):
    episodes = [
        {
            "agent": a,
            "episode": i,
            "outcome": o,
            "steps": s,
            "sim_time": s * 0.1,
            "active_sim_time": s * 0.1 * f,
            "compute_time": s * c,
            "decision_mean": c,
            "precompute_time": None,
            "final_speed": 1.0,
            "qp_fallbacks": 0,
            "nan_states": 0,
        }
        for i, (a, o, s, f, c) in enumerate(rows)
    ]
    table = table_i(pd.DataFrame.from_records(episodes), batch_size)
    assert list(table.index) == list(dict.fromkeys(r[0] for r in rows))  # agents in order of appearance
    for agent in table.index:
        mine = [e for e in episodes if e["agent"] == agent]
        ref = _reference_row(mine, batch_size)
        got = table.loc[agent]
        for key, want in ref.items():
            assert got[key] == pytest.approx(want, rel=1e-12, abs=1e-12, nan_ok=True), key
        agg = aggregate(mine, batch_size)  # the dict form the report uses is the same computation
        assert agg["collision"] == (got["collision"], got["collision_std"]) or math.isnan(agg["collision"][0])


def test_table_i_of_a_stored_run_matches_the_report(results):
    table = table_i(load_results(results))
    csv = (results / "table_I.csv").read_text().splitlines()
    assert list(table.index) == ["cbf", "inactive"] and table.loc["inactive", "episodes"] == 3
    header = csv[0].split(",")
    for line in csv[1:]:
        row = dict(zip(header, line.split(","), strict=True))  # a row has one field per column
        agent = row[header[0]]
        stored = [float(v) for k, v in row.items() if k != header[0] and v.replace(".", "").replace("-", "").isdigit()]
        for col in ("goal", "collision", "timeout", "intervention"):
            assert any(v == pytest.approx(table.loc[agent, col], abs=1e-9) for v in stored), (agent, col)
