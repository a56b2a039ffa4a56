"""How long the commands that read results take at the paper's size: compare, merge, export, report.

Run: ``python -m benchmarks.perf_results`` (``--episodes``, ``--agents``, ``--repeats``).  Writes
a Table I-sized results database (``--agents`` agents x ``--episodes`` episodes, fixed clock, the
rows' values drawn from a seeded generator with Table I's outcome mix, guardian statistics and
start fingerprints, through the store's own schema) into a scratch folder, then times, as medians
over ``--repeats``:

* ``rmm-bench compare`` of two agents over every episode (2,000 bootstrap resamples); issue 41's
  target: under 5 s for 2 x 2,048 episodes;
* ``rmm-bench merge`` of that database with a copy of itself (every episode stored twice, so every
  row is compared column by column: the worst case); target: under 10 s for two 2,048-episode
  databases;
* ``rmm-bench export`` to Parquet and to CSV;
* ``rmm-bench report`` (tables and figure), and with ``--html`` where the results page exists;
  target for the page: under 5 s for a 9-agent Table I.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np


def write_database(folder: Path, agents: int, episodes: int, seed: int = 0) -> list[str]:
    """A results directory with ``agents`` x ``episodes`` stored rows and the run's invocation."""
    from rmm_bench.config import EpisodeResult
    from rmm_bench.store import EPISODE_FIELDS, ResultsStore
    from rmm_envs.starts import world_key

    rng = np.random.default_rng(seed)
    names = [f"agent{i}" for i in range(agents)]
    env_kwargs = {"base_step": 0.1, "clock": "fixed:1", "time_accel": 10.0}
    store = ResultsStore(folder / "results.db")
    keys = {}
    cols = list(EPISODE_FIELDS)
    try:
        for a, name in enumerate(names):
            key = f"{a:016x}"
            keys[name] = key
            config = {"agent": name, "agent_kwargs": {}, "env_id": "Dubins4DParallel-v0", "env_kwargs": env_kwargs,
                      "seed": 0, "episode_timeout": 600.0, "charge_precompute": False}  # fmt: skip
            store.ensure_run(key, name, config, {"argv": ["perf"], "package_version": "perf", "git_revision": None,
                                                 "guardian": {"observation": "local", "n_obstacles": 5}})  # fmt: skip
            outcome = rng.choice(["goal", "collision", "timeout"], size=episodes, p=[0.75, 0.1, 0.15])
            steps = rng.integers(50, 1000, size=episodes)
            rows = []
            for e in range(episodes):
                r = EpisodeResult(
                    run_key=key, episode=e, agent=name, seed=1000 + e, outcome=str(outcome[e]), steps=int(steps[e]),
                    active_steps=int(steps[e] // 5), sim_time=float(steps[e]) * 0.11,
                    active_sim_time=float(steps[e] // 5) * 0.11, compute_time=float(steps[e]) * 1e-3,
                    avg_compute_time=1e-3, decision_mean=float(rng.uniform(1e-5, 1e-4)), decision_std=1e-5,
                    decision_max=1e-3, precompute_time=0.0, final_speed=float(rng.uniform(0, 2)), cum_reward=0.0,
                    qp_fallbacks=0, nan_states=0, guardian_stats=json.dumps({"takeovers": int(rng.integers(0, 9))}),
                    wall_time=0.05, finished=time.time(), cost=0.0, start=f"{e:016x}",
                )  # fmt: skip
                rows.append([r.as_row()[c] for c in cols])
            with store.db:
                store.db.executemany(
                    f"INSERT INTO episodes ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})", rows
                )
        world = world_key("Dubins4DParallel-v0", env_kwargs, 0)
        store.add_starts(world, [(e, 1000 + e, f"{e:016x}", bool(e % 13 == 0), "perf", 0.0) for e in range(episodes)])
        args = {"env": "Dubins4DParallel-v0", "clock": "fixed:1", "time_accel": 10.0, "base_step": 0.1, "seed": 0,
                "agent": ",".join(names)}  # fmt: skip
        inv = store.add_invocation("run", args, keys, episodes)
        store.finish_invocation(inv)
    finally:
        store.close()
    return names


def _median(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` over ``repeats``, what it prints discarded."""
    times = []
    for _ in range(repeats):
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=2048)
    p.add_argument("--agents", type=int, default=9)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    from rmm_bench.cli import main as bench
    from rmm_bench.compare import compare_runs
    from rmm_bench.merge import merge

    root = Path(tempfile.mkdtemp(prefix="perf_results_"))
    try:
        run = root / "run"
        run.mkdir()
        t0 = time.perf_counter()
        names = write_database(run, args.agents, args.episodes)
        size = (run / "results.db").stat().st_size
        print(f"database: {args.agents} agents x {args.episodes} episodes, {size / 1e6:.1f} MB, "
              f"written in {time.perf_counter() - t0:.1f} s")  # fmt: skip
        twin = root / "twin"
        shutil.copytree(run, twin)

        t = _median(lambda: compare_runs([run], names[:2], resamples=2000), args.repeats)
        print(f"compare, 2 agents x {args.episodes} episodes: {t:.2f} s (target < 5 s)")
        t = _median(lambda: compare_runs([run], names, resamples=2000), args.repeats)
        print(f"compare, all {args.agents} agents ({args.agents * (args.agents - 1) // 2} pairs): {t:.2f} s")

        counter = iter(range(10**6))

        def do_merge():
            merge(root / f"merged{next(counter)}", [run, twin])

        t = _median(do_merge, args.repeats)
        print(f"merge, two {args.episodes}-episode databases of {args.agents} agents, every row overlapping: "
              f"{t:.2f} s (target < 10 s)")  # fmt: skip
        for fmt in ("parquet", "csv"):
            t = _median(lambda fmt=fmt: bench(["export", str(run), "--format", fmt]), args.repeats)
            print(f"export {fmt}: {t:.2f} s")
        t = _median(lambda: bench(["report", str(run)]), args.repeats)
        print(f"report (tables and figure): {t:.2f} s")
        try:
            import rmm_bench.html  # noqa: F401
        except ImportError:
            print("report --html: not measured (no results page in this version)")
        else:
            t = _median(lambda: bench(["report", str(run), "--html"]), args.repeats)
            print(f"report --html, {args.agents}-agent Table I: {t:.2f} s (target < 5 s)")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
