"""What storing clock traces costs a wall-clock run: bytes per 1,000 episodes and run time.

Run: ``python -m benchmarks.perf_trace`` (``--agents``, ``--episodes``, ``--workers``,
``--repeats``).  Runs ``rmm-bench`` on ``Dubins4DParallel-v0`` under the wall clock (``make
run``'s setting; by default ``make run``'s agents without the two HJ rows, whose PDE solves
would only dilute the ratio) into a scratch folder, then reports:

* **storage**: the database's size with its ``clock_traces`` table and without it (a copy with
  the table dropped, both ``VACUUM``-ed), per 1,000 episodes, and the compressed bytes per lap;
* **run time**: the trace's own work timed directly, against the run's wall time in the same
  sitting: per step, the non-blocking wrapper's ``list.append`` of the lap; per episode, the
  worker's ``tuple`` of its laps, the extra bytes pickled to the parent and back, and the
  parent's ``encode_laps`` and ``INSERT`` beside the row, in the row's transaction of a WAL
  database, as the store does: the difference to storing the rows alone, medians over
  ``--repeats`` alternating, on the run's own traces.  Issue 40's limit: below 2%
  of a ``make run``.

Timing the work itself, rather than two whole runs with and without traces, keeps the figure out
of the noise of a shared machine: a whole run varies by more than the trace costs.
"""

from __future__ import annotations

import argparse
import pickle
import shutil
import sqlite3
import statistics
import tempfile
import time
from pathlib import Path

from rmm_bench.cli import main as bench_main
from rmm_bench.store import TRACE_CODEC, decode_laps, encode_laps

AGENTS = "lrmm,lrmm-paper,cbf,cbf-paper,random,inactive,brakes"


def _db_bytes(path: Path) -> int:
    con = sqlite3.connect(path)
    con.execute("PRAGMA journal_mode = DELETE")
    con.execute("VACUUM")
    con.close()
    return path.stat().st_size


def _store_seconds(traces: list[list[float]], scratch: Path, with_trace: bool) -> float:
    """Seconds to store one row per trace the way the store does (a WAL database, one
    transaction per episode), with or without the trace beside the row; with it, also the
    worker's ``tuple`` of its laps and the extra bytes pickled to the parent and back."""
    db = sqlite3.connect(scratch)
    db.execute("PRAGMA journal_mode = WAL")
    db.execute("CREATE TABLE IF NOT EXISTS e (k TEXT, episode INTEGER, outcome TEXT, steps INTEGER, stats TEXT)")
    db.execute("CREATE TABLE IF NOT EXISTS t (k TEXT, episode INTEGER, codec TEXT, n INTEGER, laps BLOB)")
    t0 = time.perf_counter()
    for i, laps in enumerate(traces):
        with db:
            db.execute("INSERT INTO e VALUES (?, ?, ?, ?, ?)", ("key", i, "goal", len(laps), '{"a": 1}'))
            if with_trace:
                trace = tuple(laps)  # the worker's copy of its laps
                pickle.loads(pickle.dumps(trace, protocol=pickle.HIGHEST_PROTOCOL))  # to the parent
                db.execute(
                    "INSERT INTO t VALUES (?, ?, ?, ?, ?)", ("key", i, TRACE_CODEC, len(trace), encode_laps(trace))
                )
    elapsed = time.perf_counter() - t0
    db.close()
    return elapsed


def _append_seconds(n: int) -> float:
    laps: list[float] = []
    append = laps.append
    t0 = time.perf_counter()
    for _ in range(n):
        append(0.0123)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--agents", default=AGENTS)
    p.add_argument("--episodes", type=int, default=32)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--repeats", type=int, default=5)
    args = p.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "res"
        argv_run = ["--agent", args.agents, "--episodes", str(args.episodes), "--batch-size", "16", "--out", str(out)]
        argv_run += ["--workers", str(args.workers), "--no-progress", "--no-figure", "--clock", "wall"]
        t0 = time.perf_counter()
        code = bench_main(argv_run)
        run_seconds = time.perf_counter() - t0
        if code not in (0, 1):
            raise SystemExit(f"rmm-bench exited {code}")
        db = out / "results.db"
        con = sqlite3.connect(db)
        rows = con.execute("SELECT n, codec, laps FROM clock_traces").fetchall()
        episodes = con.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
        con.close()
        traces = [decode_laps(blob, n, codec) for n, codec, blob in rows]
        laps = sum(len(t) for t in traces)
        blob_bytes = sum(len(blob) for _, _, blob in rows)

        with_traces = _db_bytes(db)
        bare = Path(tmp) / "bare.db"
        shutil.copy(db, bare)
        con = sqlite3.connect(bare)
        con.execute("DROP TABLE clock_traces")
        con.commit()
        con.close()
        without = _db_bytes(bare)

        diffs = []
        for i in range(args.repeats):  # alternating, so both see the same machine
            bare_s = _store_seconds(traces, Path(tmp) / f"a{i}.db", with_trace=False)
            traced_s = _store_seconds(traces, Path(tmp) / f"b{i}.db", with_trace=True)
            diffs.append(traced_s - bare_s)
        work = max(statistics.median(diffs), 0.0)
        append = statistics.median(_append_seconds(laps) for _ in range(args.repeats))

    per_k = (with_traces - without) / episodes * 1000
    print(
        f"run: {episodes} episodes ({args.agents}), {laps} laps, wall clock, {args.workers} workers: {run_seconds:.1f} s"
    )
    print(
        f"storage: {with_traces / 1e6:.2f} MB with traces, {without / 1e6:.2f} MB without: "
        f"{per_k / 1e6:.2f} MB per 1,000 episodes ({blob_bytes / laps:.2f} compressed bytes per lap)"
    )
    trace_s = work + append
    print(
        f"run time: trace work {trace_s * 1e3:.1f} ms (per-episode {work * 1e3:.1f} ms, per-step appends "
        f"{append * 1e3:.2f} ms) of a {run_seconds:.1f} s run = {100 * trace_s / run_seconds:.3f}% "
        f"(limit 2%; the run's episodes ran on {args.workers} workers, the parent's share is what adds)"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
