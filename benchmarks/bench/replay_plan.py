"""What ``rmm-bench replay`` replays: its request, and the stored episodes it selects, checked.

:func:`plan_replay` reads the results database (opened read-only) and returns one
:class:`ReplayTarget` per selected episode: the stored run (its configuration, checked to hash to
its key), the episode's row and, for a clocked run of a non-blocking env, its clock trace.  Every
reason an episode cannot be replayed is a ``ValueError`` of one line, raised before anything is
imported or simulated.  :func:`replay_agents` splits ``--agent`` into the agents of a
side-by-side replay.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass
from pathlib import Path

from rmm_bench.config import AgentRun
from rmm_bench.consent import check_consent
from rmm_bench.names import did_you_mean
from rmm_bench.runner import REPRODUCIBLE_CLOCKS
from rmm_bench.store import ResultsStore
from rmm_envs.catalog import current_id
from rmm_envs.clocks import make_clock

__all__ = ["ReplayRequest", "ReplayTarget", "plan_replay", "replay_agents"]


@dataclass(frozen=True)
class ReplayRequest:
    """``rmm-bench replay``'s arguments, validated (``results_args.parse_replay``)."""

    dir: Path
    agent: str
    episodes: tuple[int, ...] | None  # --episode (None: --where selects)
    where: str | None
    limit: int | None
    allow_errors: bool
    trust_modules: bool
    env: str | None  # --env: names the env's module for a module:Id env (and must match the stored env)
    invocation: int | None
    progress: bool
    video: Path | None = None  # --video FILE (.mp4 or .gif)
    frames: Path | None = None  # --frames DIR (one PNG per frame)
    every: int = 1  # --every K: every K-th frame (and the last)
    fps: float | None = None  # --fps (default: the episode's own pace, simulated seconds per video second)
    size: int = 512  # --size: the picture's side in pixels (the strip comes under it)
    trusted: tuple[str, ...] = ()  # --trust-module: modules the database names that may be imported


@dataclass(frozen=True)
class ReplayTarget:
    """One episode to replay: the stored run, its row, its clock trace (None: not needed)."""

    run: AgentRun
    run_key: str
    row: dict
    clock_trace: tuple[float, ...] | None
    clock_mode: str  # the run's clock mode (wall, cpu, fixed)
    nonblocking: bool


def _module_of(name: str) -> str | None:
    module, colon, _ = name.rpartition(":")
    return module if colon and module else None


def _select_run(store: ResultsStore, req: ReplayRequest) -> tuple[str, dict]:
    """The run of ``--agent`` to replay: that of ``--invocation``, else the newest stored."""
    runs = store.runs_of(req.agent)
    if not runs:  # a module:Class agent named by its class alone (its module is then not named: see _check_trust)
        stored = [r[0] for r in store.db.execute("SELECT DISTINCT agent FROM runs")]
        same = [a for a in stored if _module_of(a) and a.rpartition(":")[2] == req.agent]
        runs = store.runs_of(same[0]) if len(same) == 1 else []
    if not runs:
        agents = sorted({r[0] for r in store.db.execute("SELECT agent FROM runs")})
        raise ValueError(
            f"--agent {req.agent}: no run of {req.agent!r} is stored in {store.path}{did_you_mean(req.agent, agents)} "
            f"(expected one of its agents: {', '.join(agents) or 'none stored'})"
        )
    if req.invocation is None:
        return runs[0]["run_key"], runs[0]["config"]
    inv = store.invocation(req.invocation)  # LookupError naming the invocation
    key = inv["run_keys"].get(req.agent)
    if key is None:
        raise ValueError(
            f"--invocation {req.invocation}: it ran {', '.join(inv['run_keys']) or 'no agent'}, not {req.agent!r}"
        )
    return key, store.run_config(key)["config"]


def _agent_run(config: dict, run_key: str, store: ResultsStore) -> AgentRun:
    try:
        run = AgentRun(
            agent=config["agent"],
            agent_kwargs=config["agent_kwargs"],
            env_id=current_id(config["env_id"]),
            env_kwargs=config["env_kwargs"],
            seed=int(config["seed"]),
            episode_timeout=float(config["episode_timeout"]),
            charge_precompute=bool(config["charge_precompute"]),
            inputs=config.get("inputs") or {},
        )
    except (KeyError, TypeError, ValueError) as e:
        raise ValueError(f"run {run_key} in {store.path}: its stored configuration cannot be read ({e!r})") from None
    if run.key != run_key:
        raise ValueError(
            f"run {run_key} in {store.path}: its stored configuration hashes to {run.key}, expected {run_key}; "
            "the database was edited or written by another version"
        )
    return run


def _episode_numbers(store: ResultsStore, run_key: str, req: ReplayRequest) -> list[int]:
    if req.where is None:
        numbers = list(req.episodes or ())
    else:
        try:
            rows = store.db.execute(
                f"SELECT episode FROM episodes WHERE run_key = ? AND ({req.where}) ORDER BY episode", (run_key,)
            ).fetchall()
        except sqlite3.Error as e:
            columns = [r[1] for r in store.db.execute("PRAGMA table_info(episodes)")]
            raise ValueError(
                f"--where {req.where!r}: {e}; expected an SQL condition on the episodes table's columns "
                f"({', '.join(columns)}), e.g. \"outcome='collision'\""
            ) from None
        numbers = [int(r[0]) for r in rows]
        if req.episodes is not None:
            numbers = [i for i in numbers if i in set(req.episodes)]
        if not numbers:
            raise ValueError(f"--where {req.where!r}: no episode of {req.agent}'s run {run_key} matches")
    return numbers[: req.limit] if req.limit is not None else numbers


def _clock_mode(env_kwargs: dict) -> str:
    return make_clock(env_kwargs.get("clock", "wall")).mode


def plan_replay(store: ResultsStore, req: ReplayRequest) -> list[ReplayTarget]:
    """Every selected episode, checked (ValueError, one line, for any that cannot be replayed)
    before anything is imported or run."""
    run_key, config = _select_run(store, req)
    if req.env is not None and req.env not in (config["env_id"],):
        if current_id(req.env) != current_id(config["env_id"]):
            raise ValueError(f"--env {req.env}: {req.agent}'s run {run_key} ran on {config['env_id']!r}, expected it")
    check_consent(config, req)  # before anything is imported
    run = _agent_run(config, run_key, store)
    mode = _clock_mode(run.env_kwargs)
    nonblocking = "time_accel" in run.env_kwargs
    stored = {r["episode"]: r for r in store.episodes(run_key)}
    targets = []
    for i in _episode_numbers(store, run_key, req):
        row = stored.get(i)
        if row is None:
            span = f"0-{max(stored)}" if stored else "none"
            raise ValueError(
                f"--episode {i}: {req.agent}'s run {run_key} in {store.path} has no episode {i} "
                f"(expected one of the {len(stored)} stored: {span})"
            )
        if row["outcome"] == "error":
            error_kind = row.get("error_kind") or "guardian"
            first = (row.get("error") or "").splitlines()[0][:200] if row.get("error") else "no message"
            if error_kind == "lost_worker":
                raise ValueError(
                    f"--episode {i}: its worker was lost ({first}), so nothing of it was recorded to replay; "
                    "expected an episode with a result (rerun the run to retry it)"
                )
            if not req.allow_errors:
                raise ValueError(
                    f"--episode {i}: it ended in an error of kind {error_kind} ({first}); replayed only with --allow-errors"
                )
        trace = None
        if nonblocking and mode not in REPRODUCIBLE_CLOCKS:
            laps = store.clock_trace(run_key, i)
            if laps is None:
                why = (
                    f"{store.path} predates clock traces (schema version {store.version})"
                    if not store.has_traces()
                    else "no clock trace is stored for it"
                )
                raise ValueError(
                    f"--episode {i}: cannot be replayed: its run used the {mode!r} clock, whose decision times "
                    f"passed in the simulated world, and {why}; only its fixed-clock runs (--clock fixed:MS) "
                    "replay without one"
                )
            trace = tuple(laps)
        targets.append(ReplayTarget(run, run_key, row, trace, mode, nonblocking))
    if not targets:
        raise ValueError("--episode: no episode selected; expected an episode number, e.g. --episode 3")
    return targets


def replay_agents(req: ReplayRequest) -> tuple[str, ...]:
    """The agents ``--agent`` names: one, or a comma list (``lrmm,cbf``: replayed side by side)."""
    agents = tuple(dict.fromkeys(a.strip() for a in req.agent.split(",") if a.strip()))
    if not agents:
        raise ValueError(f"--agent {req.agent!r}: expected a stored agent, or a comma list of them (e.g. lrmm,cbf)")
    return agents
