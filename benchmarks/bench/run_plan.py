"""What a run or sweep owes before anything runs: the agents that apply, the episodes not stored, the starts.

:func:`applicable` checks every option, env and guardian (:func:`rmm_bench.run_checks.check_runs`)
and drops the agents of a named set that do not apply; :func:`plan_tasks` lists the episodes of
each :class:`~rmm_bench.config.AgentRun` not stored yet as :class:`~rmm_bench.config.EpisodeTask`
values; :func:`assess_starts` stores each world's starts (doomed or not) once, before the agents run.

Compute threads: when several workers share the machine (``--workers`` > 1, or Ray), a
guardian whose constructor takes ``threads`` (the HJ guardian's compiled solver) is built with
``threads=1`` unless ``--agent-opt AGENT.threads=N`` sets it; one worker leaves it at the
guardian's own default.  Threads are not part of the run's configuration: results do not
depend on them, and a rerun with another worker count resumes the same run.
"""

from __future__ import annotations

import os
import sys
import time

from rmm_bench.config import AgentRun, BenchConfig, EpisodeTask, accepts_argument, source_digests
from rmm_bench.run_checks import check_runs
from rmm_bench.runner import _env, episode_seed
from rmm_bench.store import ResultsStore
from rmm_envs.catalog import stored_id
from rmm_envs.starts import assess_start, has_doomed_test, start_fingerprint, world_key
from rmm_guardians.registry import load_guardian_class

__all__ = ["applicable", "assess_starts", "guardian_threads", "plan_tasks"]


def guardian_threads(agent, agent_kwargs: dict, workers: int, backend: str) -> int | None:
    """The ``threads`` a worker builds ``agent`` (its class, or its name) with (None: not passed);
    see the module docstring."""

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


def assess_starts(store: ResultsStore, runs: dict[str, AgentRun], episodes, progress: bool = False) -> int:
    """Store the start (fingerprint, doomed flag) of each of ``episodes`` (indices) of every world
    the ``runs`` meet (:func:`rmm_envs.starts.world_key`) that is not stored yet: once per world
    and episode, in this process, before the agents run, whatever the number of agents.  Envs
    without a doomed test (:func:`rmm_envs.starts.has_doomed_test`) are skipped (their rows keep
    their own fingerprints); an env this process cannot make is left to the workers, which
    report it.  Returns how many starts it stored."""

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


def _sources(run: AgentRun) -> dict[str, str]:
    """The source files of the modules ``run`` names (its agent's, its env's, its options')."""
    return source_digests(run.agent, run.env_id, agent_kwargs=run.agent_kwargs, env_kwargs=run.env_kwargs)


def applicable(config: BenchConfig) -> tuple[BenchConfig, dict]:
    """Check every option, env and guardian before anything is written (:func:`check_runs`).
    Agents of a named set (``--agent all``, ``paper``) that do not apply to the env are dropped
    from the run and listed, with the reason, on stderr; an agent named explicitly that does
    not apply is an error, as is a set of which none applies."""

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
