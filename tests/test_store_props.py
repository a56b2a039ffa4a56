"""What a rerun and a report read back from the results store (``benchmarks/bench/store.py``).

For any set of stored episodes (any indices, outcomes and error kinds, two runs in one file):
``episodes(key, n)`` is exactly the stored rows of that run with index ``0 .. n-1``, in order;
``done_episodes`` is what a rerun skips (everything but the retried failures, and guardian
errors too with ``retry_errors``); ``plan_tasks`` then asks for exactly the rest of ``0 .. n-1``;
and a stored result is replaced only where it is an error."""

from __future__ import annotations

import sqlite3

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.bench.config import AgentRun, EpisodeResult
from benchmarks.bench.run import plan_tasks
from benchmarks.bench.runner import episode_seed
from benchmarks.bench.store import RETRIED_ERRORS, ResultsStore

RUNS = {a: AgentRun(agent=a, agent_kwargs={}, env_id="Dubins4DCircles-v0", env_kwargs={}, seed=s, episode_timeout=60.0,
                    charge_precompute=False) for a, s in (("inactive", 0), ("brakes", 5))}
KINDS = ("goal", "collision", "timeout", "error:guardian", "error:timeout", "error:lost_worker")


def _result(run: AgentRun, episode: int, kind: str, tag: float = 0.0, finished: float = 0.0) -> EpisodeResult:
    outcome, _, err = kind.partition(":")
    return EpisodeResult(run_key=run.key, episode=episode, agent=run.agent, seed=episode_seed(run.seed, episode),
                         outcome=outcome, steps=episode + 1, sim_time=tag, error=f"failed ({err})" if err else None,
                         error_kind=err or None, finished=finished)


stored = st.dictionaries(st.integers(0, 24), st.sampled_from(KINDS), max_size=20)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a=stored, b=stored, n=st.integers(0, 26), retry=st.booleans())
def test_reads_are_exactly_the_stored_episodes_below_n(tmp_path, a, b, n, retry):
    path = tmp_path / "results.db"
    path.unlink(missing_ok=True)
    store = ResultsStore(path)
    try:
        for agent, eps in (("inactive", a), ("brakes", b)):
            run = RUNS[agent]
            store.ensure_run(run.key, agent, run.as_dict(), {})
            for t, (i, kind) in enumerate(sorted(eps.items(), key=lambda kv: -kv[0])):  # finished out of order
                store.add_episode(_result(run, i, kind, finished=float(t)))
        for agent, eps in (("inactive", a), ("brakes", b)):
            key = RUNS[agent].key
            rows = store.episodes(key, n)
            assert [r["episode"] for r in rows] == sorted(i for i in eps if i < n)
            assert all(r["run_key"] == key and r["agent"] == agent for r in rows)
            assert [r["outcome"] for r in rows] == [eps[i].partition(":")[0] for i in sorted(eps) if i < n]
            assert [r["episode"] for r in store.episodes(key)] == sorted(eps)
            skip = {i for i, k in eps.items()
                    if not (k.startswith("error") and (retry or k.partition(":")[2] in RETRIED_ERRORS))}
            assert store.done_episodes(key, retry_errors=retry) == skip
        tasks = plan_tasks(store, RUNS, n, workers=1, backend="local", retry_errors=retry)
        for agent, eps in (("inactive", a), ("brakes", b)):
            mine = [t for t in tasks if t.run_key == RUNS[agent].key]
            want = [i for i in range(n) if i not in eps
                    or (eps[i].startswith("error") and (retry or eps[i].partition(":")[2] in RETRIED_ERRORS))]
            assert [t.episode for t in mine] == want
            assert [t.seed for t in mine] == [episode_seed(RUNS[agent].seed, i) for i in want]
    finally:
        store.close()


@pytest.mark.parametrize("first, second, kept", [
    ("goal", "collision", "goal"),  # a result is never overwritten
    ("error:guardian", "goal", "goal"),  # an error is (a retry)
    ("error:timeout", "collision", "collision"),
    ("error:lost_worker", "error:timeout", "error:timeout"),
    ("timeout", "error:lost_worker", "timeout"),
])
def test_a_stored_result_is_replaced_only_where_it_is_an_error(tmp_path, first, second, kept):
    store = ResultsStore(tmp_path / "results.db")
    run = RUNS["inactive"]
    store.add_episode(_result(run, 3, first, tag=1.0))
    store.add_episode(_result(run, 3, second, tag=2.0))
    (row,) = store.episodes(run.key)
    assert (row["outcome"], row["error_kind"]) == (kept.partition(":")[0], kept.partition(":")[2] or None)
    assert row["sim_time"] == (1.0 if kept == first else 2.0)
    store.close()
    with sqlite3.connect(tmp_path / "results.db") as db:  # one row, the file holds no duplicate
        assert db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0] == 1
