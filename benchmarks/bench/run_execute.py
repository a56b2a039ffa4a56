"""Running a command's episodes: on local worker processes or Ray, each result stored as it arrives.

:func:`execute` records each :class:`~rmm_bench.config.AgentRun` of a
:class:`~rmm_bench.config.BenchConfig`, plans what the store lacks (:mod:`rmm_bench.run_plan`),
runs it (:func:`rmm_bench.runner.run_traced_episode` in each worker) and stores every
:class:`~rmm_bench.config.EpisodeResult`; :class:`RunFailed` is a run that could not finish.
"""

from __future__ import annotations

import sys

from rmm_bench.config import AgentRun, BenchConfig, EpisodeResult
from rmm_bench.run_plan import assess_starts, plan_tasks
from rmm_bench.runner import EpisodeRecord, hard_timeout, lost_episode, run_traced_episode
from rmm_bench.store import RETRIED_ERRORS, ResultsStore
from rmm_envs.pool import TaskLost, WorkersLost, run_local, run_ray

__all__ = ["RunFailed", "execute", "unfinished_message"]


class RunFailed(RuntimeError):
    """The run stopped on an error, or left episodes without a result (exit status 1)."""


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


def unfinished_message(unfinished: dict[str, int], store: ResultsStore) -> str:
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
