"""``rmm-bench``: run guardians over seeded episodes and reproduce the paper's Table I.

    rmm-bench --agent lrmm --episodes 2048                 # run (the default command)
    rmm-bench --agent all --episodes 64                    # every available guardian
    rmm-bench --agent lrmm,cbf --clock fixed:2             # reproducible: every decision takes 2 ms
    rmm-bench --agent mypkg.guard:MyGuardian               # a third-party guardian
    rmm-bench report results/                              # rebuild the last run's table from the database
    rmm-bench sweep --agent lrmm,cbf --latency 0,1,5,20,50 # collision rate against decision latency

Results go to ``--out`` (default ``results/``): ``results.db`` (SQLite: every episode and run),
``table_I.md``/``.csv``/``.tex`` and ``outcomes.png`` (rates and compute time against collisions);
a sweep writes ``latency_sweep.md`` and ``latency_sweep.png``.  Rerunning the same command,
or adding ``--resume``, finishes an interrupted run without repeating stored episodes.

Clock modes (``--clock``): ``wall`` (default, the paper's: real time between steps, scaled by
``--time-accel``, passes in the world; results depend on the machine and on how many workers
share its cores), ``cpu`` (the worker's own CPU time: insensitive to other processes) and
``fixed:MS`` (every decision takes exactly MS ms: bit-reproducible whatever the worker count).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from benchmarks.bench.metrics import aggregate
from benchmarks.bench.report import PAPER_TABLE_I, format_tables, plot_latency, plot_outcomes
from benchmarks.bench.runner import episode_seed, run_episode, run_key
from benchmarks.bench.store import ResultsStore

ENVS = ("Dubins4DParallel-v0", "Dubins4DCircles-v0")


def _provenance(argv) -> dict:
    import rmm_envs

    rev = None
    try:
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5,
                             cwd=Path(__file__).resolve().parent).stdout.strip() or None
    except Exception:
        pass
    return {"package_version": rmm_envs.__version__, "git_revision": rev, "argv": list(argv),
            "python": platform.python_version(), "platform": platform.platform(), "cpus": os.cpu_count()}


def _agents(spec: str) -> list[str]:
    from guardians import available_guardians
    from guardians.registry import load_guardian_class

    available = available_guardians()
    names = available if spec.strip() == "all" else [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise ValueError(f"--agent is empty; choose from {available}, 'all' or 'module:Class'")
    for n in names:
        load_guardian_class(n)  # raises ValueError listing the valid names
    return names


def _agent_opts(items: list[str], agents: list[str]) -> dict[str, dict]:
    """Parse ``AGENT.KEY=VALUE`` options (VALUE as JSON, else a string)."""
    out: dict[str, dict] = {}
    for item in items:
        head, eq, value = item.partition("=")
        agent, dot, key = head.rpartition(".")
        if not eq or not dot or not agent or not key:
            raise ValueError(f"--agent-opt {item!r}: expected AGENT.KEY=VALUE, e.g. hj.margin=0.3")
        if agent not in agents:
            raise ValueError(f"--agent-opt {item!r}: agent {agent!r} is not in this run ({agents})")
        try:
            parsed = json.loads(value)
        except json.JSONDecodeError:
            parsed = value
        out.setdefault(agent, {})[key] = parsed
    return out


def _guardian_info(agent: str) -> tuple[str, str]:
    from guardians.registry import load_guardian_class

    cls = load_guardian_class(agent)
    return getattr(cls, "observation_type", "?"), getattr(cls, "name", agent)


def _run_configs(args, agents) -> dict[str, dict]:
    env_kwargs = {}
    if args.env == "Dubins4DParallel-v0":
        env_kwargs = {"time_accel": args.time_accel, "base_step": args.base_step, "clock": args.clock}
    else:
        env_kwargs = {"clock": args.clock}
    opts = _agent_opts(getattr(args, "agent_opt", None) or [], agents)
    out = {}
    for a in agents:
        cfg = {"agent": a, "agent_kwargs": opts.get(a, {}), "env_id": args.env, "env_kwargs": env_kwargs, "seed": args.seed,
               "episode_timeout": args.episode_timeout, "charge_precompute": args.charge_precompute}
        out[a] = cfg
    return out


def execute(store: ResultsStore, configs: dict[str, dict], episodes: int, workers: int, backend: str,
            ray_address: str | None, progress: bool, provenance: dict) -> None:
    tasks = []
    for agent, cfg in configs.items():
        key = run_key(cfg)
        store.ensure_run(key, agent, cfg, provenance)
        done = store.done_episodes(key)
        for i in range(episodes):
            if i not in done:
                # the kernel threads are not part of the run's configuration (results do not
                # depend on them): one per worker when several workers share the machine
                tasks.append({**cfg, "run_key": key, "episode": i, "seed": episode_seed(cfg["seed"], i),
                              "kernel_threads": 1 if (workers > 1 or backend == "ray") else None})
    if not tasks:
        return
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), unit="ep", disable=not progress, dynamic_ncols=True, desc="episodes")
    counts: dict[str, dict[str, int]] = {}

    def record(row):
        store.add_episode(row)
        c = counts.setdefault(row["agent"], {})
        c[row["outcome"]] = c.get(row["outcome"], 0) + 1
        bar.set_postfix_str("; ".join(f"{a}: " + " ".join(f"{k[0]}{v}" for k, v in sorted(c.items())) for a, c in counts.items())[-120:])
        bar.update(1)

    from rmm_envs.parallel import run_local, run_ray

    try:
        results = run_ray(run_episode, tasks, ray_address) if backend == "ray" else run_local(run_episode, tasks, workers)
        for row in results:
            record(row)
    finally:
        bar.close()


def table_rows(store: ResultsStore, run_keys: dict[str, str], episodes, batch_size: int = 64) -> list[dict]:
    """Aggregate rows; ``episodes`` is one count for every agent or a dict per agent."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    rows = []
    for agent, key in run_keys.items():
        n = episodes[agent] if isinstance(episodes, dict) else episodes
        eps = store.episodes(key, n)
        cfg = store.run_config(key)["config"]
        obs_type, _ = _guardian_info(agent) if _safe_import(agent) else ("?", agent)
        n_obst = gym.make(cfg["env_id"]).unwrapped.n_obstacles
        agg = aggregate(eps, batch_size)
        rows.append({"agent": agent, "obs": obs_type, "n_obst": n_obst, **agg})
    return rows


def _safe_import(agent) -> bool:
    try:
        from guardians.registry import load_guardian_class

        load_guardian_class(agent)
        return True
    except Exception:
        return False


def write_report(store: ResultsStore, out: Path, invs: list[dict] | dict, batch_size: int = 64, quiet: bool = False) -> str:
    """Tables and figures for one recorded command, or several merged (later ones win per agent)."""
    invs = [invs] if isinstance(invs, dict) else list(invs)
    run_keys, episodes = {}, {}
    for inv in invs:
        for agent, key in inv["run_keys"].items():
            run_keys[agent], episodes[agent] = key, inv["episodes"]
    rows = table_rows(store, run_keys, episodes, batch_size)
    tables = format_tables(rows)
    (out / "table_I.md").write_text(tables["md"])
    (out / "table_I.csv").write_text(tables["csv"])
    (out / "table_I.tex").write_text(tables["tex"])
    plot_outcomes(rows, out / "outcomes.png")
    paper = format_tables([{"agent": a, "episodes": 2048, "errors": 0, "qp_fallbacks": 0, "precompute_s": (0, 0),
                            "obs": p["obs"], "n_obst": p["n_obst"], **{k: p[k] for k in ("compute_ms", "goal", "collision", "timeout", "intervention")}}
                           for a, p in PAPER_TABLE_I.items() if a in run_keys])["md"]
    args = invs[-1]["args"]
    counts = sorted(set(episodes.values()))
    text = (f"Table I: {args.get('env')}, clock {args.get('clock')}, time accel {args.get('time_accel')}, seed {args.get('seed')}, "
            f"{'/'.join(map(str, counts))} episodes per agent (results in {out})\n\n{tables['md']}\nThe paper's Table I for the same agents:\n\n{paper}")
    if not quiet:
        print(text)
    return text


def cmd_run(args, argv) -> int:
    agents = _agents(args.agent)
    configs = _run_configs(args, agents)  # validates every option before anything is written
    out = Path(args.out)
    store = ResultsStore(out / "results.db")
    keys = {a: run_key(c) for a, c in configs.items()}
    inv = store.add_invocation("run", vars(args), keys, args.episodes)
    t0 = time.perf_counter()
    try:
        execute(store, configs, args.episodes, args.workers, args.backend, args.ray_address, not args.no_progress, _provenance(argv))
    except KeyboardInterrupt:
        store.finish_invocation(inv, "interrupted")
        print(f"\ninterrupted: finished episodes are saved in {out / 'results.db'}; rerun the same command to finish", file=sys.stderr)
        return 130
    store.finish_invocation(inv)
    print(f"finished in {time.perf_counter() - t0:.1f} s")
    write_report(store, out, store.invocation(inv), args.batch_size)
    return 0


def cmd_report(args) -> int:
    path = Path(args.dir)
    if not (path / "results.db").exists():
        print(f"rmm-bench report: error: no results.db in {path}", file=sys.stderr)
        return 2
    store = ResultsStore(path / "results.db")
    if args.invocation:
        invs = [store.invocation(i) for i in args.invocation]
    else:
        invs = [store.invocation(None, kind="run")]
    write_report(store, path, invs, args.batch_size)
    return 0


def cmd_sweep(args, argv) -> int:
    agents = _agents(args.agent)
    try:
        latencies = [float(x) for x in args.latency.split(",") if x.strip()]
    except ValueError:
        latencies = []
    if not latencies or any(x < 0 for x in latencies):
        raise ValueError(f"--latency must be a comma list of non-negative milliseconds, got {args.latency!r}")
    args.clock = f"fixed:{latencies[0]:g}"
    _run_configs(args, agents)  # validates the options before anything is written
    out = Path(args.out)
    store = ResultsStore(out / "results.db")
    series: dict[str, list] = {a: [] for a in agents}
    lines = ["| agent | " + " | ".join(f"{x:g} ms" for x in latencies) + " |", "|---|" + "---|" * len(latencies)]
    table: dict[str, list[str]] = {a: [] for a in agents}
    for lat in latencies:
        args.clock = f"fixed:{lat:g}"
        configs = _run_configs(args, agents)
        keys = {a: run_key(c) for a, c in configs.items()}
        inv = store.add_invocation("sweep", vars(args) | {"latency_ms": lat}, keys, args.episodes)
        execute(store, configs, args.episodes, args.workers, args.backend, args.ray_address, not args.no_progress, _provenance(argv))
        store.finish_invocation(inv)
        for agent, key in keys.items():
            agg = aggregate(store.episodes(key, args.episodes), args.batch_size)
            series[agent].append((lat, agg["collision"][0], agg["collision"][1]))
            table[agent].append(f"{agg['collision'][0]:.1f} ± {agg['collision'][1]:.1f}")
    lines += [f"| {a} | " + " | ".join(table[a]) + " |" for a in agents]
    md = (f"Collision rate [% episodes] against added decision latency (fixed clock, time accel {args.time_accel}, "
          f"{args.episodes} episodes, seed {args.seed})\n\n" + "\n".join(lines) + "\n")
    (out / "latency_sweep.md").write_text(md)
    plot_latency(series, out / "latency_sweep.png")
    print(md)
    return 0


def _common(p: argparse.ArgumentParser, default_agent: str) -> None:
    p.add_argument("--agent", default=default_agent, help="guardian name, comma list, 'all', or module:Class (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=2048, help="episodes per agent (default: %(default)s)")
    p.add_argument("--env", default="Dubins4DParallel-v0", choices=ENVS, help="environment (default: %(default)s)")
    p.add_argument("--time-accel", type=float, default=10.0, help="sim seconds per clock second (default: %(default)s)")
    p.add_argument("--base-step", type=float, default=0.1, help="sim seconds added every step (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="master seed; episode i's seed derives from it (default: %(default)s)")
    p.add_argument("--out", default="results", help="output directory (default: %(default)s)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="worker processes (default: the core count)")
    p.add_argument("--backend", default="local", choices=["local", "ray"], help="local processes or Ray tasks (default: %(default)s)")
    p.add_argument("--ray-address", default=None, help="Ray cluster address (default: start a local Ray)")
    p.add_argument("--agent-opt", action="append", metavar="AGENT.KEY=VALUE",
                   help="a guardian constructor argument (VALUE as JSON), e.g. hj.margin=0.3 or lrmm.threshold=0.9; repeatable")
    p.add_argument("--episode-timeout", type=float, default=600.0, help="wall seconds before an episode is recorded as an error (default: %(default)s)")
    p.add_argument("--charge-precompute", action="store_true", help="charge a guardian's reset (e.g. an HJ solve) to the first step's clock")
    p.add_argument("--batch-size", type=int, default=64, help="episodes per batch for the rate statistics (default: %(default)s)")
    p.add_argument("--resume", action="store_true", help="finish an interrupted run (rerunning the same command does the same)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rmm-bench", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    _common(p, "lrmm")
    p.add_argument("--clock", default="wall", help="wall (default), cpu, or fixed:MS")
    return p


def build_report_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rmm-bench report", description="Rebuild Table I and the figures from a results database.")
    p.add_argument("dir", help="results directory holding results.db")
    p.add_argument("--invocation", type=int, action="append", default=None,
                   help="which recorded run (default: the last); repeat to merge several into one table")
    p.add_argument("--batch-size", type=int, default=64)
    return p


def build_sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="rmm-bench sweep", description="Collision rate against added decision latency (fixed-latency clock).")
    _common(p, "lrmm,cbf")
    p.add_argument("--latency", default="0,1,5,20,50", help="comma list of decision latencies in ms (default: %(default)s)")
    p.set_defaults(episodes=256)
    return p


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if argv and argv[0] == "report":
            return cmd_report(build_report_parser().parse_args(argv[1:]))
        if argv and argv[0] == "sweep":
            args = build_sweep_parser().parse_args(argv[1:])
            _validate(args)
            return cmd_sweep(args, argv)
        if argv and argv[0] == "run":
            argv = argv[1:]
        args = build_parser().parse_args(argv)
        _validate(args)
        from rmm_envs.clocks import make_clock

        make_clock(args.clock)
        return cmd_run(args, argv)
    except (ValueError, RuntimeError, LookupError) as e:
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 2


def _validate(args) -> None:
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.batch_size < 1:
        raise ValueError(f"--batch-size must be >= 1, got {args.batch_size}")


if __name__ == "__main__":
    sys.exit(main())
