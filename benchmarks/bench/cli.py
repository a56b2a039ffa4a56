"""``rmm-bench``: run guardians over seeded episodes and reproduce the paper's Table I.

    rmm-bench --agent lrmm --episodes 2048                 # run (the default command)
    rmm-bench --agent all --episodes 64                    # every guardian at its defaults
    rmm-bench --agent paper --episodes 64                  # the paper's agents with the paper's rules
    rmm-bench --agent lrmm,cbf --clock fixed:2             # reproducible: every decision takes 2 ms
    rmm-bench --agent mypkg.guard:MyGuardian               # a third-party guardian
    rmm-bench report results/                              # rebuild the last run's table from the database
    rmm-bench --agent lrmm --episodes 2048 --retry-errors  # after fixing a guardian: rerun its error episodes
    rmm-bench sweep --agent lrmm,cbf --latency 0,1,5,20,50 # collision rate against decision latency

Results go to ``--out`` (default ``results/``): ``results.db`` (SQLite: every episode and run),
``table_I.md``/``.csv``/``.tex`` and ``outcomes.png`` (rates and compute time against collisions);
a sweep writes ``latency_sweep.md`` and ``latency_sweep.png``.  Rerunning the same command,
or adding ``--resume``, finishes an interrupted run without repeating stored episodes.

Clock modes (``--clock``): ``wall`` (default, the paper's: real time between steps, scaled by
``--time-accel``, passes in the world; results depend on the machine and on how many workers
share its cores), ``cpu`` (the worker's own CPU time: insensitive to other processes) and
``fixed:MS`` (every decision takes exactly MS ms: bit-reproducible whatever the worker count).

Failures.  Every option is checked before any episode runs, including building the env and
each guardian with its ``--agent-opt`` values: a bad one exits with status 2 and one line
naming the flag.  While running, an episode whose guardian raises is stored as that
guardian's error (a result: the Errors column; ``--retry-errors`` runs them again).  An
episode over ``--episode-timeout`` (default 600 s: generous, as a worker's first episode also
pays for imports and, for ``hj``, a value-function solve of tens of seconds before it is
cached) or whose worker process died (out of memory, a crash, a guardian
calling ``os._exit``) is a failure of the run, not a result: it is stored with its cause, a
fresh worker takes over, and any rerun retries it.  After ``max(4, 2 x workers)`` episodes in
a row lost their worker the run stops (a cause that kills every worker, such as too little
memory, would otherwise restart workers for every remaining episode).  A run that leaves
episodes without a result exits with status 1 and says how to finish; Ctrl-C exits 130; both
keep every finished episode.  ``rmm-bench report`` prints how many episodes each agent
actually has and flags a run that was killed (its invocation still says ``running`` but its
process is gone).
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
from benchmarks.bench.runner import episode_seed, hard_timeout, lost_episode, run_episode, run_key
from benchmarks.bench.store import RETRIED_ERRORS, ResultsStore

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
    from guardians.registry import guardian_set, load_guardian_class

    available = available_guardians()
    names = guardian_set(spec)
    if names is None:
        names = [s.strip() for s in spec.split(",") if s.strip()]
    if not names:
        raise ValueError(f"--agent is empty; choose from {available}, 'all', 'paper' or 'module:Class'")
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


class RunFailed(RuntimeError):
    """The run stopped on an error, or left episodes without a result (exit status 1)."""


def _flag_for(message: str, env_kwargs: dict) -> str:
    for k in env_kwargs:
        if k in message:
            return f"--{k.replace('_', '-')} {env_kwargs[k]}"
    return f"--env {env_kwargs}"


def _check_run(configs: dict[str, dict]) -> dict[str, dict]:
    """Build the env and every guardian as the workers will, before any episode runs.

    Raises ValueError naming the flag and value at fault; returns, per agent, what ``report``
    prints later without importing anything (observation type, obstacle count)."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401
    from guardians import make_guardian

    meta: dict[str, dict] = {}
    envs: dict[str, int] = {}
    for agent, cfg in configs.items():
        ekey = json.dumps([cfg["env_id"], cfg["env_kwargs"]], sort_keys=True)
        if ekey not in envs:
            try:
                env = gym.make(cfg["env_id"], **cfg["env_kwargs"])
            except Exception as e:
                raise ValueError(f"{_flag_for(str(e), cfg['env_kwargs'])}: {e}") from None
            envs[ekey] = int(getattr(env.unwrapped, "n_obstacles", -1))
            env.close()
        try:
            guardian = make_guardian(agent, **cfg["agent_kwargs"])
        except Exception as e:
            opts = " ".join(f"{agent}.{k}={v if isinstance(v, str) else json.dumps(v)}" for k, v in cfg["agent_kwargs"].items())
            where = f"--agent-opt {opts}" if opts else f"--agent {agent}"
            raise ValueError(f"{where}: the guardian cannot be built: {type(e).__name__}: {e}") from None
        meta[agent] = {"observation": str(getattr(guardian, "observation_type", "?")), "n_obstacles": envs[ekey]}
    return meta


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
            ray_address: str | None, progress: bool, provenance: dict, meta: dict[str, dict] | None = None,
            retry_errors: bool = False, invocation: int | None = None) -> dict[str, int]:
    """Run every episode not stored yet; returns, per agent, how many of this call's episodes
    ended without a result (time limit, lost worker).  Raises :class:`RunFailed` if too many
    episodes in a row lost their worker."""
    from rmm_envs.parallel import TaskLost, WorkersLost, run_local, run_ray

    tasks = []
    for agent, cfg in configs.items():
        key = run_key(cfg)
        store.ensure_run(key, agent, cfg, provenance | {"guardian": (meta or {}).get(agent, {})})
        done = store.done_episodes(key, retry_errors)
        for i in range(episodes):
            if i not in done:
                # the kernel threads are not part of the run's configuration (results do not
                # depend on them): one per worker when several workers share the machine
                tasks.append({**cfg, "run_key": key, "episode": i, "seed": episode_seed(cfg["seed"], i),
                              "kernel_threads": 1 if (workers > 1 or backend == "ray") else None})
    unfinished = {a: 0 for a in configs}
    if not tasks:
        return unfinished
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), unit="ep", disable=not progress, dynamic_ncols=True, desc="episodes")
    counts: dict[str, dict[str, int]] = {}

    def record(row):
        store.add_episode(row, invocation)
        if row.get("error_kind") in RETRIED_ERRORS:
            unfinished[row["agent"]] += 1
        c = counts.setdefault(row["agent"], {})
        label = "lost" if row.get("error_kind") == "lost_worker" else row["outcome"]
        c[label] = c.get(label, 0) + 1
        bar.set_postfix_str("; ".join(f"{a}: " + " ".join(f"{k[0]}{v}" for k, v in sorted(c.items())) for a, c in counts.items())[-120:])
        bar.update(1)

    max_lost = max(4, 2 * workers)
    try:
        if backend == "ray":
            results = run_ray(run_episode, tasks, ray_address, max_lost_in_a_row=max_lost)
        else:
            limit = max(hard_timeout(c["episode_timeout"]) for c in configs.values())
            results = run_local(run_episode, tasks, workers, task_timeout=limit, max_lost_in_a_row=max_lost)
        for res in results:
            record(lost_episode(res.task, res.cause) if isinstance(res, TaskLost) else res)
    except WorkersLost as e:
        raise RunFailed(f"{e}: {sum(unfinished.values())} episodes lost their worker (see the error column of "
                        f"{store.path}); fix the cause (fewer --workers if memory ran out) and rerun the same command") from None
    finally:
        bar.close()
    return unfinished


def _legacy_meta(agent: str, cfg: dict) -> dict:
    """Observation type and obstacle count for runs stored before they were recorded: only
    built-in guardian names and this package's envs are looked up (our own modules); a name
    from the database is never imported."""
    from guardians.registry import BUILTIN, load_guardian_class

    meta = {"observation": "?", "n_obstacles": "?"}
    if agent in BUILTIN:
        try:
            meta["observation"] = getattr(load_guardian_class(agent), "observation_type", "?")
        except Exception:
            pass
    if cfg.get("env_id") in ENVS:
        import gymnasium as gym

        import rmm_envs  # noqa: F401

        meta["n_obstacles"] = gym.make(cfg["env_id"]).unwrapped.n_obstacles
    return meta


def table_rows(store: ResultsStore, run_keys: dict[str, str], episodes, batch_size: int = 64) -> list[dict]:
    """Aggregate rows from the stored rows alone; ``episodes`` is one count for every agent or a
    dict per agent.  Each row also says how many episodes have a result (``with_result``: all
    stored but those over the time limit or lost with their worker)."""
    rows = []
    for agent, key in run_keys.items():
        n = episodes[agent] if isinstance(episodes, dict) else episodes
        eps = store.episodes(key, n)
        run = store.run_config(key)
        meta = run["provenance"].get("guardian") or _legacy_meta(agent, run["config"])
        agg = aggregate(eps, batch_size)
        with_result = sum(1 for e in eps if not (e["outcome"] == "error" and e.get("error_kind") in RETRIED_ERRORS))
        rows.append({"agent": agent, "obs": meta.get("observation", "?"), "n_obst": meta.get("n_obstacles", "?"),
                     "requested": n, "with_result": with_result, **agg})
    return rows


def _completeness(rows: list[dict], invs: list[dict]) -> str:
    """'' when every agent has a result for every requested episode, else what is missing and why."""
    short = [r for r in rows if r["with_result"] < r["requested"]]
    if not short:
        return ""
    have = ", ".join(f"{r['agent']} {r['with_result']} of {r['requested']}" for r in short)
    why = []
    lost = sum(r["episodes"] - r["with_result"] for r in short)
    if lost:
        why.append(f"{lost} stored over the time limit or lost with their worker")
    for inv in invs:
        state = inv.get("state", inv["status"])
        if state == "stale":
            why.append(f"invocation {inv['id']} was killed: it is marked running but its process {inv['pid']} is gone")
        elif state == "running":
            why.append(f"invocation {inv['id']} is still running (process {inv['pid']} on {inv['host']})")
        elif state in ("interrupted", "failed"):
            msg = inv.get("message") or ""
            detail = f": {msg}" if msg and "ended without a result" not in msg else ""
            why.append(f"invocation {inv['id']} {state}{detail}")
    return (f"INCOMPLETE: episodes with a result: {have}" + (f" ({'; '.join(why)})" if why else "")
            + ". Rerun the same command to finish; the table covers the stored episodes only.\n")


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
                           for a, p in PAPER_TABLE_I.items() if a in run_keys or f"{a}-paper" in run_keys])["md"]
    args = invs[-1]["args"]
    counts = sorted(set(episodes.values()))
    text = (f"Table I: {args.get('env')}, clock {args.get('clock')}, time accel {args.get('time_accel')}, seed {args.get('seed')}, "
            f"{'/'.join(map(str, counts))} episodes requested per agent (results in {out})\n{_completeness(rows, invs)}\n"
            f"{tables['md']}\nThe paper's Table I for the same agents:\n\n{paper}")
    if not quiet:
        print(text)
    return text


def _unfinished_message(unfinished: dict[str, int], store: ResultsStore) -> str:
    lacking = {a: n for a, n in unfinished.items() if n}
    if not lacking:
        return ""
    return (f"{sum(lacking.values())} episodes ended without a result ({', '.join(f'{a}: {n}' for a, n in lacking.items())}): "
            f"over --episode-timeout or their worker died (causes in the error column of {store.path}); "
            "the table counts them as errors; rerun the same command to retry them")


def _invoke(store: ResultsStore, kind: str, args, argv, configs: dict, meta: dict, record_args: dict) -> tuple[int, str]:
    """Record an invocation, run it, and end it as finished, interrupted or failed."""
    keys = {a: run_key(c) for a, c in configs.items()}
    inv = store.add_invocation(kind, record_args, keys, args.episodes)
    try:
        unfinished = execute(store, configs, args.episodes, args.workers, args.backend, args.ray_address, not args.no_progress,
                             _provenance(argv), meta, args.retry_errors, inv)
    except KeyboardInterrupt:
        store.finish_invocation(inv, "interrupted", "Ctrl-C")
        raise
    except BaseException as e:
        store.finish_invocation(inv, "failed", f"{type(e).__name__}: {e}"[:1000])
        raise
    msg = _unfinished_message(unfinished, store)
    store.finish_invocation(inv, "failed" if msg else "finished", msg or None)
    return inv, msg


def _interrupted(out: Path) -> int:
    print(f"\ninterrupted: finished episodes are saved in {out / 'results.db'}; rerun the same command to finish", file=sys.stderr)
    return 130


def cmd_run(args, argv) -> int:
    agents = _agents(args.agent)
    configs = _run_configs(args, agents)
    meta = _check_run(configs)  # every option, env and guardian checked before anything is written
    out = Path(args.out)
    store = ResultsStore(out / "results.db")
    try:
        store.mark_stale_invocations()
        t0 = time.perf_counter()
        try:
            inv, msg = _invoke(store, "run", args, argv, configs, meta, vars(args))
        except KeyboardInterrupt:
            return _interrupted(out)
        print(f"finished in {time.perf_counter() - t0:.1f} s")
        write_report(store, out, store.invocation(inv), args.batch_size)
        if msg:
            print(f"rmm-bench: {msg}", file=sys.stderr)
            return 1
        return 0
    finally:
        store.close()


def cmd_report(args) -> int:
    path = Path(args.dir)
    if not (path / "results.db").is_file():
        print(f"rmm-bench report: error: no results.db in {path}", file=sys.stderr)
        return 2
    store = ResultsStore(path / "results.db")
    try:
        if args.invocation:
            invs = [store.invocation(i) for i in args.invocation]
        else:
            invs = [store.invocation(None, kind="run")]
        write_report(store, path, invs, args.batch_size)
    finally:
        store.close()
    return 0


def cmd_sweep(args, argv) -> int:
    agents = _agents(args.agent)
    try:
        latencies = [float(x) for x in args.latency.split(",") if x.strip()]
    except ValueError:
        latencies = []
    if not latencies or any(not 0 <= x < float("inf") for x in latencies):
        raise ValueError(f"--latency must be a comma list of non-negative milliseconds, got {args.latency!r}")
    args.clock = f"fixed:{latencies[0]:g}"
    meta = _check_run(_run_configs(args, agents))  # validates the options before anything is written
    out = Path(args.out)
    store = ResultsStore(out / "results.db")
    series: dict[str, list] = {a: [] for a in agents}
    lines = ["| agent | " + " | ".join(f"{x:g} ms" for x in latencies) + " |", "|---|" + "---|" * len(latencies)]
    table: dict[str, list[str]] = {a: [] for a in agents}
    failed = []
    try:
        store.mark_stale_invocations()
        for lat in latencies:
            args.clock = f"fixed:{lat:g}"
            configs = _run_configs(args, agents)
            try:
                _, msg = _invoke(store, "sweep", args, argv, configs, meta, vars(args) | {"latency_ms": lat})
            except KeyboardInterrupt:
                return _interrupted(out)
            if msg:
                failed.append(f"{lat:g} ms: {msg}")
            for agent, cfg in configs.items():
                agg = aggregate(store.episodes(run_key(cfg), args.episodes), args.batch_size)
                series[agent].append((lat, agg["collision"][0], agg["collision"][1]))
                table[agent].append(f"{agg['collision'][0]:.1f} ± {agg['collision'][1]:.1f}")
    finally:
        store.close()
    lines += [f"| {a} | " + " | ".join(table[a]) + " |" for a in agents]
    md = (f"Collision rate [% episodes] against added decision latency (fixed clock, time accel {args.time_accel}, "
          f"{args.episodes} episodes, seed {args.seed})\n\n" + "\n".join(lines) + "\n")
    (out / "latency_sweep.md").write_text(md)
    plot_latency(series, out / "latency_sweep.png")
    print(md)
    if failed:
        print("rmm-bench sweep: " + " | ".join(failed), file=sys.stderr)
        return 1
    return 0


def _common(p: argparse.ArgumentParser, default_agent: str) -> None:
    p.add_argument("--agent", default=default_agent, help="guardian name, comma list, 'all' (defaults), 'paper' (the paper's rules), or module:Class (default: %(default)s)")
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
    p.add_argument("--episode-timeout", type=float, default=600.0,
                   help="wall seconds before an episode is stopped; it is stored as a failure that a rerun retries (default: %(default)s)")
    p.add_argument("--charge-precompute", action="store_true", help="charge a guardian's reset (e.g. an HJ solve) to the first step's clock")
    p.add_argument("--batch-size", type=int, default=64, help="episodes per batch for the rate statistics (default: %(default)s)")
    p.add_argument("--resume", action="store_true",
                   help="finish an interrupted run: runs missing episodes and retries those over the time limit or lost with their worker "
                        "(rerunning the same command does the same)")
    p.add_argument("--retry-errors", action="store_true",
                   help="also run again the episodes stored as guardian errors (after fixing the guardian or its options)")
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

        try:
            make_clock(args.clock)
        except ValueError as e:
            raise ValueError(f"--clock {args.clock}: {e}") from None
        return cmd_run(args, argv)
    except RunFailed as e:
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 1
    except (ValueError, RuntimeError, LookupError) as e:
        print(f"rmm-bench: error: {e}", file=sys.stderr)
        return 2


def _validate(args) -> None:
    """Options that need no env or guardian; :func:`_check_run` checks the rest."""
    import math

    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.batch_size < 1:
        raise ValueError(f"--batch-size must be >= 1, got {args.batch_size}")
    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    if not (math.isfinite(args.episode_timeout) and args.episode_timeout > 0):
        raise ValueError(f"--episode-timeout must be a positive, finite number of seconds, got {args.episode_timeout:g}")


if __name__ == "__main__":
    sys.exit(main())
