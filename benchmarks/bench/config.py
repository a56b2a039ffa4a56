"""Typed configuration of ``rmm-bench``: what the command line asked for, what a worker runs, what it returns.

* :class:`BenchConfig`: one ``rmm-bench`` command, parsed and validated once (``run_args.py``);
  never changed afterwards (a latency sweep derives one config per latency with
  :meth:`BenchConfig.with_clock`).
* :class:`AgentRun`: one agent under one configuration: exactly what determines an
  episode's result apart from its index.  Its :meth:`~AgentRun.as_dict` is what the store
  keeps in ``runs.config`` and what :attr:`~AgentRun.key` (the ``run_key``) hashes, with the
  same keys and values as databases written before these classes existed, so ``report`` and
  ``--resume`` read them unchanged, plus ``inputs`` when the run reads files: the SHA-256 of
  the bytes of every file the guardian or the env reads (:func:`input_digests`, from
  :mod:`rmm_bench.inputs`), so a model
  file replaced between two commands makes a new run instead of one row mixing two models,
  and the source file of the module of a ``module:Class`` agent, a ``module:Id`` env or a
  ``module:Name`` in the options (a strategy of one's own; :func:`source_digests`), so editing
  one's own guardian, simulator or strategy makes a new run too.
* :class:`EpisodeTask`: what a worker receives: the run, the episode index, its derived seed,
  and the guardian's compute threads (not part of the run: results do not depend on them).
* :class:`EpisodeResult`: what a worker returns and the store writes: one row of the
  ``episodes`` table, one field per column (``None`` is SQL ``NULL``).

All are frozen dataclasses of plain values (dicts of JSON values for options), so they pickle
to worker processes and Ray tasks and compare by value.  Their dict fields are copies taken at
construction: treat them as read-only.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field

from rmm_bench.inputs import (  # re-exported: the harness imports them from here
    PROJECT_PACKAGES,
    InputChanged,
    changed_inputs,
    file_sha256,
    input_digests,
    module_name,
    portable_path,
    resolve_input,
    run_modules,
    source_digests,
)
from rmm_envs.catalog import stored_id
from rmm_guardians.registry import accepts_argument  # noqa: F401  (re-exported: the runner and the checks use it from here)

__all__ = [
    "PROJECT_PACKAGES",
    "AgentRun",
    "BenchConfig",
    "EpisodeResult",
    "EpisodeTask",
    "InputChanged",
    "accepts_argument",
    "changed_inputs",
    "file_sha256",
    "input_digests",
    "module_name",
    "portable_path",
    "resolve_input",
    "run_input_digests",
    "run_key",
    "run_modules",
    "source_digests",
]


def run_key(config: dict) -> str:
    """The run's identity in the store: the first 16 hex digits of the SHA-256 of its sorted JSON."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:16]


def _json_copy(name: str, value: dict) -> dict:
    """A deep copy of ``value`` through JSON: what the store will hold, refused if it cannot."""
    try:
        return json.loads(json.dumps(dict(value), sort_keys=True))
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must hold JSON values (it is stored and hashed), got {value!r}: {e}") from None


def parse_shard(text: str) -> tuple[int, int]:
    """``"K/N"`` -> ``(K, N)`` with ``1 <= K <= N``; anything else is a ``ValueError`` naming it."""
    k, slash, n = str(text).strip().partition("/")
    try:
        if not slash:
            raise ValueError
        kk, nn = int(k), int(n)
    except ValueError:
        raise ValueError(f"--shard {text!r}: expected K/N, two whole numbers with 1 <= K <= N (e.g. 1/2)") from None
    if not 1 <= kk <= nn:
        raise ValueError(f"--shard {text}: expected 1 <= K <= N (share K of N shares), got K={kk}, N={nn}")
    return kk, nn


def shard_episodes(episodes: int, shard: tuple[int, int] | None) -> list[int]:
    """The episode indices of ``0 .. episodes-1`` in ``shard`` ``(K, N)``: those with ``i mod N
    == K - 1`` (balanced shares, the same on every machine); all of them when ``shard`` is None."""
    if shard is None:
        return list(range(episodes))
    k, n = shard
    return list(range(k - 1, episodes, n))


@dataclass(frozen=True)
class AgentRun:
    """One agent on one env configuration; ``agent_kwargs`` are its constructor arguments."""

    agent: str
    agent_kwargs: dict
    env_id: str
    env_kwargs: dict
    seed: int
    episode_timeout: float
    charge_precompute: bool
    inputs: dict = field(default_factory=dict)  # path -> SHA-256 of every file read (input_digests)

    def __post_init__(self) -> None:
        object.__setattr__(self, "agent_kwargs", _json_copy("agent_kwargs", self.agent_kwargs))
        object.__setattr__(self, "env_kwargs", _json_copy("env_kwargs", self.env_kwargs))
        object.__setattr__(self, "inputs", _json_copy("inputs", self.inputs))

    def as_dict(self) -> dict:
        """The stored configuration (``runs.config``), as every version of the store wrote it, plus
        ``inputs`` for a run that reads files.  The env is stored under the id its results were
        first recorded under (:func:`rmm_envs.catalog.stored_id`), so runs stored before an id
        changed keep their keys."""
        out = {
            "agent": self.agent,
            "agent_kwargs": self.agent_kwargs,
            "env_id": stored_id(self.env_id),
            "env_kwargs": self.env_kwargs,
            "seed": self.seed,
            "episode_timeout": self.episode_timeout,
            "charge_precompute": self.charge_precompute,
        }
        return out | ({"inputs": self.inputs} if self.inputs else {})

    @property
    def key(self) -> str:
        return run_key(self.as_dict())


def run_input_digests(guardian, run: AgentRun, base: str | None = None) -> dict[str, str]:
    """Every file ``run`` reads as this process sees it now (what its ``inputs`` recorded when it
    was keyed): :func:`~rmm_bench.inputs.input_digests` of the guardian and the options, and
    :func:`~rmm_bench.inputs.source_digests` of the agent's and the env's modules."""
    out = input_digests(guardian, run.agent_kwargs, run.env_kwargs) | source_digests(
        run.agent, run.env_id, base, run.agent_kwargs, run.env_kwargs
    )
    return dict(sorted(out.items()))


@dataclass(frozen=True)
class EpisodeTask:
    """Episode ``episode`` of ``run``, with env seed ``seed`` (derived from the run's seed).

    ``threads``: passed as the guardian's ``threads`` argument when not None (the runner sets
    it only for guardians whose constructor takes one and whose options do not already)."""

    run: AgentRun
    run_key: str
    episode: int
    seed: int
    threads: int | None = None
    #: folders the worker searches for the modules the run names, after the installed packages
    #: (the directory ``rmm-bench`` ran in, so ``module:Class`` and ``module:Id`` import from there
    #: in every worker: :func:`rmm_envs.user_modules.search_user_folders`; not part of the run's identity)
    import_path: tuple[str, ...] = ()

    @property
    def agent(self) -> str:
        return self.run.agent

    def guardian_kwargs(self) -> dict:
        return self.run.agent_kwargs | ({} if self.threads is None else {"threads": int(self.threads)})


@dataclass(frozen=True)
class EpisodeResult:
    """One row of the store's ``episodes`` table, one field per column (this class owns the
    schema: :data:`rmm_bench.store.EPISODE_FIELDS` is derived from it, a field without
    ``None`` in its type being ``NOT NULL``)."""

    run_key: str
    episode: int
    agent: str
    seed: int
    outcome: str  # goal / collision / timeout / error
    steps: int | None = None
    active_steps: int | None = None
    sim_time: float | None = None
    active_sim_time: float | None = None
    compute_time: float | None = None  # the env clock's total agent time, s
    avg_compute_time: float | None = None  # per step, s (Table I's policy compute time)
    decision_mean: float | None = None  # guardian.act() wall time per call, s
    decision_std: float | None = None
    decision_max: float | None = None
    precompute_time: float | None = None  # guardian.reset(), s (e.g. an HJ solve)
    final_speed: float | None = None
    cum_reward: float | None = None
    qp_fallbacks: int | None = None
    nan_states: int | None = None
    guardian_stats: str | None = None
    error: str | None = None
    wall_time: float | None = None
    finished: float | None = None
    error_kind: str | None = (
        None  # guardian / timeout / lost_worker / input_changed / env (None unless outcome is error)
    )
    cost: float | None = None  # the episode's summed info["cost"] (None: the env reports none)
    start: str | None = None  # rmm_envs.starts.start_fingerprint of the episode's start (schema version 3)

    def as_row(self) -> dict:
        return dataclasses.asdict(self)

    def replace(self, **changes) -> EpisodeResult:
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class BenchConfig:
    """One ``rmm-bench`` run or sweep, validated (see ``run_args.py``).

    ``parsed`` is the command line's arguments as argparse named them (stored with the
    invocation, where ``report`` reads the env, clock, time acceleration and seed it prints)."""

    agents: tuple[str, ...]
    agent_kwargs: dict  # agent -> its --agent-opt values
    env_id: str
    env_kwargs: dict  # what the env is built with: the options of this command it accepts
    clock: str
    seed: int
    episodes: int
    out: str
    workers: int
    backend: str
    ray_address: str | None
    episode_timeout: float
    charge_precompute: bool
    batch_size: int
    retry_errors: bool
    progress: bool
    figure: bool = True  # draw outcomes.png (a sweep: latency_sweep.png) after the tables
    parsed: dict = field(default_factory=dict)
    latencies: tuple[float, ...] = ()  # a sweep's decision latencies, ms
    agent_set: str | None = None  # the named set --agent gave ("all", "paper"), or None for named agents
    agent_inputs: dict = field(
        default_factory=dict
    )  # agent -> the files its run reads (input_digests), set once checked
    #: agent -> its guardian class, resolved once when the command is parsed (neither stored nor hashed)
    agent_classes: dict = field(default_factory=dict, compare=False, repr=False)
    shard: tuple[int, int] | None = None  # (K, N): run only share K of N of the episodes (--shard K/N)

    def episode_indices(self) -> list[int]:
        """The episodes this command owes: ``0 .. episodes-1``, or its shard's share of them."""
        return shard_episodes(self.episodes, self.shard)

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "agent_kwargs", {a: _json_copy(f"--agent-opt {a}", kw) for a, kw in self.agent_kwargs.items()}
        )
        object.__setattr__(
            self, "agent_inputs", {a: _json_copy(f"{a} inputs", kw) for a, kw in self.agent_inputs.items()}
        )
        object.__setattr__(self, "env_kwargs", _json_copy("env_kwargs", self.env_kwargs))
        object.__setattr__(self, "parsed", _json_copy("arguments", self.parsed))

    def with_clock(self, clock: str) -> BenchConfig:
        """The same command under another clock (a sweep's latency); the env gets it only if it
        took this run's clock."""
        env_kwargs = self.env_kwargs | {"clock": clock} if "clock" in self.env_kwargs else self.env_kwargs
        return dataclasses.replace(self, clock=clock, env_kwargs=env_kwargs)

    def without(self, agents) -> BenchConfig:
        """The same command without ``agents`` (those of a named set that do not apply to the env)."""
        drop = set(agents)
        return dataclasses.replace(
            self,
            agents=tuple(a for a in self.agents if a not in drop),
            agent_kwargs={a: kw for a, kw in self.agent_kwargs.items() if a not in drop},
            agent_inputs={a: d for a, d in self.agent_inputs.items() if a not in drop},
            agent_classes={a: c for a, c in self.agent_classes.items() if a not in drop},
        )

    def with_inputs(self, inputs: dict[str, dict]) -> BenchConfig:
        """The same command with the files each agent's run reads (agent -> path -> SHA-256)."""
        return dataclasses.replace(self, agent_inputs=dict(inputs))

    def agent_runs(self) -> dict[str, AgentRun]:
        return {
            a: AgentRun(
                agent=a,
                agent_kwargs=self.agent_kwargs.get(a, {}),
                env_id=self.env_id,
                env_kwargs=self.env_kwargs,
                seed=self.seed,
                episode_timeout=self.episode_timeout,
                charge_precompute=self.charge_precompute,
                inputs=self.agent_inputs.get(a, {}),
            )
            for a in self.agents
        }
