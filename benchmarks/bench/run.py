"""The run and sweep commands: plan the episodes a command still owes, run them, record the invocation.

Each agent of a :class:`~rmm_bench.config.BenchConfig` is one
:class:`~rmm_bench.config.AgentRun` in the store; :func:`plan_tasks` lists its episodes
not stored yet as :class:`~rmm_bench.config.EpisodeTask` values, :func:`execute` runs
them on local worker processes or Ray and stores each :class:`~rmm_bench.config.EpisodeResult`
as it arrives.

Compute threads: when several workers share the machine (``--workers`` > 1, or Ray), a
guardian whose constructor takes ``threads`` (the HJ guardian's compiled solver) is built with
``threads=1`` unless ``--agent-opt AGENT.threads=N`` sets it; one worker leaves it at the
guardian's own default.  Threads are not part of the run's configuration: results do not
depend on them, and a rerun with another worker count resumes the same run.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from pathlib import Path

from rmm_bench.config import AgentRun, BenchConfig, EpisodeResult, EpisodeTask, accepts_argument, source_digests
from rmm_bench.metrics import aggregate
from rmm_bench.names import md_cell
from rmm_bench.report import plot_latency, write_report
from rmm_bench.runner import EpisodeRecord, episode_seed, hard_timeout, lost_episode, run_traced_episode
from rmm_bench.store import RETRIED_ERRORS, ResultsStore

__all__ = [
    "RunFailed",
    "assess_starts",
    "cmd_run",
    "cmd_sweep",
    "done_line",
    "env_error_lines",
    "execute",
    "guardian_error_lines",
    "plan_tasks",
]


class RunFailed(RuntimeError):
    """The run stopped on an error, or left episodes without a result (exit status 1)."""


def _provenance(argv) -> dict:
    import rmm_envs

    rev = None
    try:
        rev = (
            subprocess.run(
                ["git", "rev-parse", "--short", "HEAD"],
                capture_output=True,
                text=True,
                timeout=5,
                cwd=Path(__file__).resolve().parent,
            ).stdout.strip()
            or None
        )
    except Exception:
        pass
    return {
        "package_version": rmm_envs.__version__,
        "git_revision": rev,
        "argv": list(argv),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
    }


def guardian_threads(agent, agent_kwargs: dict, workers: int, backend: str) -> int | None:
    """The ``threads`` a worker builds ``agent`` (its class, or its name) with (None: not passed);
    see the module docstring."""
    from rmm_guardians.registry import load_guardian_class

    if not (workers > 1 or backend == "ray") or "threads" in agent_kwargs:
        return None
    return 1 if accepts_argument(load_guardian_class(agent) if isinstance(agent, str) else agent, "threads") else None


def plan_tasks(
    store: ResultsStore,
    runs: dict[str, AgentRun],
    episodes: int,
    workers: int,
    backend: str,
    retry_errors: bool = False,
    classes: dict | None = None,
    indices: list[int] | None = None,
) -> list[EpisodeTask]:
    """The episodes ``0 .. episodes-1`` (or ``indices``, a shard's) of each run that the store
    lacks (or holds as a retried failure); ``classes``: each agent's class as the command
    resolved it (else resolved by name)."""
    tasks = []
    for agent, run in runs.items():
        key = run.key
        threads = guardian_threads((classes or {}).get(agent, agent), run.agent_kwargs, workers, backend)
        done = store.done_episodes(key, retry_errors)
        tasks += [
            EpisodeTask(
                run=run,
                run_key=key,
                episode=i,
                seed=episode_seed(run.seed, i),
                threads=threads,
                import_path=(os.getcwd(),),
            )
            for i in (range(episodes) if indices is None else indices)
            if i not in done
        ]
    return tasks


def _announce_new_runs(store: ResultsStore, runs: dict[str, AgentRun]) -> None:
    """One line per agent whose files (a model) differ from those of episodes stored for the same
    command: the run key covers the files' bytes, so this command starts a new run instead of
    appending to the old one."""
    for agent, run in runs.items():
        for old in store.superseded_runs(run.key, run.as_dict()):
            if not old["episodes"]:
                continue
            if old["inputs"]:
                paths = sorted(set(old["inputs"]) | set(run.inputs))
                what = ", ".join(
                    f"{p} (sha256 {old['inputs'].get(p, 'none')[:12]} then, {run.inputs.get(p, 'none')[:12]} now)"
                    for p in paths
                    if old["inputs"].get(p) != run.inputs.get(p)
                )
            else:
                what = f"{', '.join(run.inputs)} (not recorded by the version that stored them)"
            print(
                f"rmm-bench: {agent}: {old['episodes']} episodes in {store.path} were run with other files: {what}; "
                f"this command starts a new run (run {run.key}) instead of mixing them; the old episodes stay under "
                f"run {old['run_key']}",
                file=sys.stderr,
            )


def assess_starts(store: ResultsStore, runs: dict[str, AgentRun], episodes, progress: bool = False) -> int:
    """Store the start (fingerprint, doomed flag) of each of ``episodes`` (indices) of every world
    the ``runs`` meet (:func:`rmm_envs.starts.world_key`) that is not stored yet: once per world
    and episode, in this process, before the agents run, whatever the number of agents.  Envs
    without a doomed test (:func:`rmm_envs.starts.has_doomed_test`) are skipped (their rows keep
    their own fingerprints); an env this process cannot make is left to the workers, which
    report it.  Returns how many starts it stored."""
    from rmm_bench.runner import _env
    from rmm_envs.catalog import stored_id
    from rmm_envs.starts import assess_start, has_doomed_test, start_fingerprint, world_key

    worlds: dict[str, AgentRun] = {}
    for run in runs.values():
        worlds.setdefault(world_key(stored_id(run.env_id), run.env_kwargs, run.seed), run)
    stored = 0
    for key, run in worlds.items():
        missing = [i for i in episodes if i not in store.starts(key)]
        if not missing:
            continue
        try:
            env = _env(run.env_id, run.env_kwargs)
        except Exception:  # the workers report it, as an env error of each episode
            continue
        if not has_doomed_test(env):
            continue
        from tqdm import tqdm

        rows = []
        for i in tqdm(missing, unit="start", disable=not progress, dynamic_ncols=True, desc="starts", leave=False):
            seed = episode_seed(run.seed, i)
            obs, _ = env.reset(seed=seed)
            t0 = time.perf_counter()
            verdict = assess_start(env)
            rows.append(
                (i, seed, start_fingerprint(env, obs), verdict.doomed, verdict.method, time.perf_counter() - t0)
            )
            if len(rows) >= 256:  # a long assessment keeps what it did if interrupted
                store.add_starts(key, rows)
                stored, rows = stored + len(rows), []
        store.add_starts(key, rows)
        stored += len(rows)
    return stored


def execute(
    store: ResultsStore,
    config: BenchConfig,
    provenance: dict,
    meta: dict[str, dict] | None = None,
    invocation: int | None = None,
    tally: dict[str, int] | None = None,
) -> dict[str, int]:
    """Run every episode of ``config`` not stored yet; returns, per agent, how many of this
    call's episodes ended without a result (time limit, lost worker).  ``tally``, when given,
    receives ``reused`` (the requested episodes answered from the store) and ``ran`` (those this
    call runs).  Raises :class:`RunFailed` if too many episodes in a row lost their worker."""
    from rmm_envs.pool import TaskLost, WorkersLost, run_local, run_ray

    runs = config.agent_runs()
    _announce_new_runs(store, runs)
    for agent, run in runs.items():
        store.ensure_run(run.key, agent, run.as_dict(), provenance | {"guardian": (meta or {}).get(agent, {})})
    indices = config.episode_indices()
    assess_starts(store, runs, indices, config.progress)
    tasks = plan_tasks(
        store, runs, config.episodes, config.workers, config.backend, config.retry_errors, config.agent_classes, indices
    )
    unfinished = {a: 0 for a in runs}
    if tally is not None:
        tally.update(reused=len(runs) * len(indices) - len(tasks), ran=len(tasks))
    if not tasks:
        return unfinished
    from tqdm import tqdm

    bar = tqdm(total=len(tasks), unit="ep", disable=not config.progress, dynamic_ncols=True, desc="episodes")
    counts: dict[str, dict[str, int]] = {}

    def record(result: EpisodeResult, clock_trace: tuple[float, ...] | None = None):
        store.add_episode(result, invocation, clock_trace)
        if result.error_kind in RETRIED_ERRORS:
            unfinished[result.agent] += 1
        c = counts.setdefault(result.agent, {})
        label = "lost" if result.error_kind == "lost_worker" else result.outcome
        c[label] = c.get(label, 0) + 1
        bar.set_postfix_str(
            "; ".join(f"{a}: " + " ".join(f"{k[0]}{v}" for k, v in sorted(c.items())) for a, c in counts.items())[-120:]
        )
        bar.update(1)

    max_lost = max(4, 2 * config.workers)
    try:
        if config.backend == "ray":
            results = run_ray(run_traced_episode, tasks, config.ray_address, max_lost_in_a_row=max_lost)
        else:
            results = run_local(
                run_traced_episode,
                tasks,
                config.workers,
                task_timeout=hard_timeout(config.episode_timeout),
                max_lost_in_a_row=max_lost,
            )
        for res in results:
            if isinstance(res, TaskLost):
                record(lost_episode(res.task, res.cause))
            elif isinstance(res, EpisodeRecord):
                record(res.result, res.clock_trace)
            else:  # pragma: no cover - the pools yield what the task function returns
                raise TypeError(f"a worker returned {type(res).__name__}, expected an EpisodeRecord")
    except WorkersLost as e:
        raise RunFailed(
            f"{e}: {sum(unfinished.values())} episodes lost their worker (see the error column of "
            f"{store.path}); fix the cause (fewer --workers if memory ran out) and rerun the same command"
        ) from None
    finally:
        bar.close()
    return unfinished


def _unfinished_message(unfinished: dict[str, int], store: ResultsStore) -> str:
    lacking = {a: n for a, n in unfinished.items() if n}
    if not lacking:
        return ""
    return (
        f"{sum(lacking.values())} episodes ended without a result ({', '.join(f'{a}: {n}' for a, n in lacking.items())}): "
        f"over --episode-timeout, their worker died, a file they read changed, their worker could not make the env "
        f"or the env raised "
        f"(causes in the error column of {store.path}); "
        "the table counts them as errors; rerun the same command to retry them"
    )


def guardian_error_lines(store: ResultsStore, run_keys: dict[str, str], episodes: int) -> list[str]:
    """One line per agent whose first ``episodes`` stored episodes hold guardian errors: the
    count and the first error.  Those episodes count as failures in the rates (see
    :mod:`rmm_bench.metrics`); the command exits with status 1 so they are never missed."""
    lines = []
    for agent, key in run_keys.items():
        errs = [
            e
            for e in store.episodes(key, episodes)
            if e["outcome"] == "error" and (e["error_kind"] or "guardian") == "guardian"
        ]
        if errs:
            first = (errs[0]["error"] or "").splitlines()[0][:300] if errs[0]["error"] else "no message"
            lines.append(
                f"{agent}: {len(errs)} of {episodes} episodes ended in a guardian error, counted as failures in the "
                f"rates (first, episode {errs[0]['episode']}: {first}); fix the guardian or its --agent-opt values "
                "and rerun with --retry-errors"
            )
    return lines


def env_error_lines(store: ResultsStore, run_keys: dict[str, str], episodes: int, env_id: str) -> list[str]:
    """Up to two lines naming ``env_id`` for episodes of this command that ended in an error of
    kind ``env``: those whose worker could not make the env, and those in which the env itself
    raised (its ``reset`` or ``step``, e.g. its driver; or it ended an episode without the
    contract's statistics), each with the count and the first cause.  Failures of the run (a
    rerun retries them), never guardian errors."""
    errs = [
        e
        for key in run_keys.values()
        for e in store.episodes(key, episodes)
        if e["outcome"] == "error" and e["error_kind"] == "env"
    ]
    unmade = [e for e in errs if (e["error"] or "").startswith("EnvUnavailable")]
    raised = [e for e in errs if not (e["error"] or "").startswith("EnvUnavailable")]
    lines = []
    if unmade:
        first = (unmade[0]["error"] or "no message").splitlines()[0][:400]
        lines.append(
            f"--env {env_id}: {len(unmade)} episodes could not make the env in their worker, a failure of the run, "
            f"not of a guardian (first: {first}); make the env importable in every worker and rerun the same command"
        )
    if raised:
        first = (raised[0]["error"] or "no message").splitlines()[0][:400]
        lines.append(
            f"--env {env_id}: {len(raised)} episodes ended in an error of the env itself (its reset or step, "
            f"e.g. its driver), not of a guardian, and have no result (first, episode {raised[0]['episode']}: "
            f"{first}); fix the env (the traceback in the error column of {store.path} ends where it raised) "
            "and rerun the same command"
        )
    return lines


def _invoke(
    store: ResultsStore,
    kind: str,
    config: BenchConfig,
    argv,
    meta: dict,
    record_args: dict,
    tally: dict[str, int] | None = None,
) -> tuple[int, str]:
    """Record an invocation, run it, and end it as finished, interrupted or failed (``tally``:
    :func:`execute`'s)."""
    keys = {a: r.key for a, r in config.agent_runs().items()}
    inv = store.add_invocation(kind, record_args, keys, config.episodes)
    try:
        unfinished = execute(store, config, _provenance(argv), meta, inv, tally)
    except KeyboardInterrupt:
        store.finish_invocation(inv, "interrupted", "Ctrl-C")
        raise
    except BaseException as e:
        store.finish_invocation(inv, "failed", f"{type(e).__name__}: {e}"[:1000])
        raise
    msg = _unfinished_message(unfinished, store)
    store.finish_invocation(inv, "failed" if msg else "finished", msg or None)
    return inv, msg


def _episodes(n: int) -> str:
    return f"{n} episode{'' if n == 1 else 's'}"


def done_line(reused: int, ran: int, seconds: float) -> str:
    """What a run says when it ends: the episodes it ran and how long they took, and the stored
    episodes it reused (all of them: it ran nothing, so no time is worth giving)."""
    if not ran:
        return f"reused {reused} stored episode{'' if reused == 1 else 's'}: none left to run"
    line = f"finished in {seconds:.1f} s: ran {_episodes(ran)}"
    return line + (f", reused {reused} stored" if reused else "")


def _interrupted(out: Path) -> int:
    print(
        f"\ninterrupted: finished episodes are saved in {out / 'results.db'}; rerun the same command to finish",
        file=sys.stderr,
    )
    return 130


def _sources(run: AgentRun) -> dict[str, str]:
    """The source files of the modules ``run`` names (its agent's, its env's, its options')."""
    return source_digests(run.agent, run.env_id, agent_kwargs=run.agent_kwargs, env_kwargs=run.env_kwargs)


def applicable(config: BenchConfig) -> tuple[BenchConfig, dict]:
    """Check every option, env and guardian before anything is written (:func:`check_runs`).
    Agents of a named set (``--agent all``, ``paper``) that do not apply to the env are dropped
    from the run and listed, with the reason, on stderr; an agent named explicitly that does
    not apply is an error, as is a set of which none applies."""
    from rmm_bench.checks import check_runs

    meta = check_runs(config.agent_runs(), skip_inapplicable=config.agent_set is not None, classes=config.agent_classes)
    skipped = {a: m["skipped"] for a, m in meta.items() if "skipped" in m}
    if skipped:
        if len(skipped) == len(config.agents):
            raise ValueError(
                f"--agent {config.agent_set}: no guardian of the set applies to --env {config.env_id}: "
                + "; ".join(f"{a}: {r}" for a, r in skipped.items())
            )
        for agent, reason in skipped.items():
            print(
                f"rmm-bench: --agent {config.agent_set}: {agent} does not apply to --env {config.env_id}, "
                f"skipped: {reason}",
                file=sys.stderr,
            )
        config = config.without(skipped)
        meta = {a: m for a, m in meta.items() if a not in skipped}
    runs = config.agent_runs()
    config = config.with_inputs(
        {  # the files each guardian and option read, and the source of each module the run names (agent, env, options)
            a: dict(sorted((m.pop("inputs", {}) | _sources(runs[a])).items())) for a, m in meta.items()
        }
    )
    return config, meta


def cmd_run(config: BenchConfig, argv) -> int:
    config, meta = applicable(config)  # every option, env and guardian checked before anything is written
    out = Path(config.out)
    store = ResultsStore(out / "results.db")
    try:
        store.mark_stale_invocations()
        t0 = time.perf_counter()
        tally: dict[str, int] = {}
        try:
            inv, msg = _invoke(store, "run", config, argv, meta, config.parsed, tally)
        except KeyboardInterrupt:
            return _interrupted(out)
        print(done_line(tally.get("reused", 0), tally.get("ran", 0), time.perf_counter() - t0))
        record = store.invocation(inv)
        write_report(store, out, record, config.batch_size, figure=config.figure)
        errors = env_error_lines(store, record["run_keys"], config.episodes, config.env_id) + guardian_error_lines(
            store, record["run_keys"], config.episodes
        )
        for line in ([msg] if msg else []) + errors:
            print(f"rmm-bench: {line}", file=sys.stderr)
        return 1 if msg or errors else 0
    finally:
        store.close()


def cmd_sweep(config: BenchConfig, argv) -> int:
    config, meta = applicable(config)  # validates the options before anything is written
    out = Path(config.out)
    store = ResultsStore(out / "results.db")
    agents, latencies = config.agents, config.latencies
    series: dict[str, list] = {a: [] for a in agents}
    lines = ["| agent | " + " | ".join(f"{x:g} ms" for x in latencies) + " |", "|---|" + "---|" * len(latencies)]
    table: dict[str, list[str]] = {a: [] for a in agents}
    failed = []
    try:
        store.mark_stale_invocations()
        for lat in latencies:
            at = config.with_clock(f"fixed:{lat:g}")
            try:
                _, msg = _invoke(store, "sweep", at, argv, meta, at.parsed | {"clock": at.clock, "latency_ms": lat})
            except KeyboardInterrupt:
                return _interrupted(out)
            keys = {a: r.key for a, r in at.agent_runs().items()}
            failed += [
                f"{lat:g} ms: {line}"
                for line in ([msg] if msg else [])
                + env_error_lines(store, keys, at.episodes, at.env_id)
                + guardian_error_lines(store, keys, at.episodes)
            ]
            for agent, run in at.agent_runs().items():
                agg = aggregate(store.episodes(run.key, at.episodes), at.batch_size)
                series[agent].append((lat, agg["collision"][0], agg["collision"][1]))
                table[agent].append(f"{agg['collision'][0]:.1f} ± {agg['collision'][1]:.1f}")
    finally:
        store.close()
    lines += [f"| {md_cell(a)} | " + " | ".join(table[a]) + " |" for a in agents]
    md = (
        f"Collision rate [% episodes] against added decision latency (fixed clock, time accel {config.parsed['time_accel']}, "
        f"{config.episodes} episodes, seed {config.seed})\n\n" + "\n".join(lines) + "\n"
    )
    (out / "latency_sweep.md").write_text(md)
    if config.figure:
        plot_latency(series, out / "latency_sweep.png")
    else:  # one from an earlier sweep would not match the table
        (out / "latency_sweep.png").unlink(missing_ok=True)
    print(md)
    if failed:
        for line in failed:
            print(f"rmm-bench sweep: {line}", file=sys.stderr)
        return 1
    return 0
