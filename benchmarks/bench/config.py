"""Typed configuration of ``rmm-bench``: what the command line asked for, what a worker runs, what it returns.

* :class:`BenchConfig`: one ``rmm-bench`` command, parsed and validated once (``args.py``);
  never changed afterwards (a latency sweep derives one config per latency with
  :meth:`BenchConfig.with_clock`).
* :class:`AgentRun`: one agent under one configuration: exactly what determines an
  episode's result apart from its index.  Its :meth:`~AgentRun.as_dict` is what the store
  keeps in ``runs.config`` and what :attr:`~AgentRun.key` (the ``run_key``) hashes, with the
  same keys and values as databases written before these classes existed, so ``report`` and
  ``--resume`` read them unchanged, plus ``inputs`` when the run reads files: the SHA-256 of
  the bytes of every file the guardian or the env reads (:func:`input_digests`), so a model
  file replaced between two commands makes a new run instead of one row mixing two models,
  and the source file of the module of a ``module:Class`` agent or a ``module:Id`` env
  (:func:`source_digests`), so editing one's own guardian or simulator makes a new run too.
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
import importlib.util
import json
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path

from rmm_envs.catalog import stored_id
from rmm_guardians.registry import accepts_argument  # noqa: F401  (re-exported: the runner and the checks use it from here)

__all__ = [
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
    "run_input_digests",
    "run_key",
    "source_digests",
]


def import_from(paths) -> None:
    """Put ``paths`` first on ``sys.path`` (in order, each once), as ``python -m`` puts the
    current directory: ``module:Class`` agents and ``module:Id`` envs import from there."""
    for path in reversed(tuple(paths)):
        if path in sys.path:
            sys.path.remove(path)
        sys.path.insert(0, path)


def run_key(config: dict) -> str:
    """The run's identity in the store: the first 16 hex digits of the SHA-256 of its sorted JSON."""
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:16]


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of the bytes of the file ``path``, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _strings(value):
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _strings(v)


def input_digests(guardian, *options: dict) -> dict[str, str]:
    """Every file a run reads, path -> SHA-256 of its bytes: each string option (of the guardian
    or the env) naming a regular file, and the files the guardian reports it read
    (:meth:`rmm_guardians.base.Guardian.input_files`, e.g. a shipped model)."""
    out: dict[str, str] = {}
    for opts in options:
        for text in _strings(opts):
            try:
                if len(text) < 4096 and Path(text).is_file():
                    out[text] = file_sha256(text)
            except (OSError, ValueError):  # unreadable or not a path: the guardian or env reports it when it reads it
                continue
    reported = getattr(guardian, "input_files", None)
    if callable(reported):
        out.update({str(k): str(v) for k, v in reported().items()})
    return dict(sorted((portable_path(k), v) for k, v in out.items()))


#: the project's packages: a file inside one is named by its place in the package
PROJECT_PACKAGES = ("rmm_envs", "rmm_guardians", "rmm_bench")


def _package_dir(name: str) -> Path | None:
    spec = importlib.util.find_spec(name)
    origin = spec.origin if spec is not None else None
    return Path(origin).resolve().parent if origin else None


def portable_path(path: str) -> str:
    """A file inside one of the project's installed packages (a shipped model) as
    ``package/relative/path``, the same on every machine and checkout, so the same run has the
    same key wherever it runs; any other path as given."""
    try:
        full = Path(path).resolve()
    except (OSError, RuntimeError):
        return path
    for name in PROJECT_PACKAGES:
        root = _package_dir(name)
        if root is not None and full.is_relative_to(root):
            return f"{name}/{full.relative_to(root).as_posix()}"
    return path


def resolve_input(key: str) -> Path:
    """The file an ``inputs`` key names on this machine: the inverse of :func:`portable_path`."""
    head, _, rest = key.partition("/")
    if head in PROJECT_PACKAGES and rest and not Path(key).is_absolute():
        root = _package_dir(head)
        if root is not None:
            return root / rest
    return Path(key)


def module_name(spec: str, env: bool = False) -> str | None:
    """The module of a ``module:Class`` agent (``env=False``) or a ``module:Id`` env id, as the
    registry and :func:`rmm_envs.env_plugins.resolve_env_id` split them; None for a bare name
    (a built-in guardian or env, an entry point)."""
    module, colon, rest = spec.rpartition(":") if env else spec.partition(":")
    return module if colon and module and rest else None


def _module_file(name: str) -> str | None:
    """The file module ``name`` is (or would be) loaded from: its own ``.py`` file, a package's
    ``__init__.py``; None for a namespace package, a built-in module or one not found."""
    mod = sys.modules.get(name)
    origin = getattr(mod, "__file__", None) if mod is not None else None
    if origin is None and mod is None:
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):  # a parent package missing or failing: the import reports it
            spec = None
        origin = spec.origin if spec is not None and spec.has_location else None
    return origin if isinstance(origin, str) and os.path.isfile(origin) else None


def _path_key(path: str, base: str | None) -> str:
    """``path`` relative to ``base`` (default: the current directory) when it lies under it, so a
    project moved or cloned elsewhere keeps its run keys; else absolute."""
    full = os.path.abspath(path)
    try:
        rel = os.path.relpath(full, base or os.getcwd())
    except ValueError:  # another drive
        return full
    return full if rel == os.pardir or rel.startswith(os.pardir + os.sep) else rel


def source_digests(agent: str, env_id: str, base: str | None = None) -> dict[str, str]:
    """The source files of the user's own code a run imports, path -> SHA-256: the module of a
    ``module:Class`` agent and of a ``module:Id`` env (its own ``.py`` file; a package's
    ``__init__.py``), so editing it starts a new run.  Files that module imports are not
    covered.  Built-in guardians and envs (bare names) have none: their run keys are unchanged.
    The module must be imported already (or importable); one that is not gives no entry (the
    import reports it).  ``base``: the folder paths are relative to (the directory
    ``rmm-bench`` ran in; default, the current one)."""
    out: dict[str, str] = {}
    for name in (module_name(agent), module_name(env_id, env=True)):
        path = _module_file(name) if name else None
        if path is not None:
            try:
                out[_path_key(path, base)] = file_sha256(path)
            except OSError:  # unreadable now: the run's check names it as unreadable
                continue
    return out


def run_input_digests(guardian, run: AgentRun, base: str | None = None) -> dict[str, str]:
    """Every file ``run`` reads as this process sees it now (what its ``inputs`` recorded when it
    was keyed): :func:`input_digests` of the guardian and the options, and
    :func:`source_digests` of the agent's and the env's modules."""
    out = input_digests(guardian, run.agent_kwargs, run.env_kwargs) | source_digests(run.agent, run.env_id, base)
    return dict(sorted(out.items()))


class InputChanged(RuntimeError):
    """A file the run reads no longer has the bytes the run was started with."""


def changed_inputs(recorded: dict[str, str], now: dict[str, str]) -> str:
    """'' if every file of ``recorded`` still has its digest in ``now``, else one clause per changed file."""
    return "; ".join(
        f"{path} (sha256 {digest[:12]}... when the run was keyed, "
        f"{now[path][:12] + '...' if now.get(path) else 'unreadable'} now)"
        for path, digest in recorded.items()
        if now.get(path) != digest
    )


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
    #: folders the worker puts first on ``sys.path`` before importing the agent and the env (the
    #: directory ``rmm-bench`` ran in, so ``module:Class`` and ``module:Id`` import from there in
    #: every worker, as ``python -m`` would; not part of the run's identity)
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
    """One ``rmm-bench`` run or sweep, validated (see ``args.py``).

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
