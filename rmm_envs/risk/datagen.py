"""Dataset generation (the paper's Algorithm 2) as ``rmm-datagen``.

For each procedurally generated obstacle configuration: sample valid states, observe them,
label them with the sampling-tree estimator.  Example (the paper's Dubins4D scale)::

    rmm-datagen --env Dubins4DCircles-v0 --configs 274 --samples-per-config 128 --seed 0 --out data/d4

Output directory:

* ``metadata.json``: env id and arguments, estimator parameters, seed, sizes, package version.
* ``shard-NNNNN.parquet``: rows for a fixed block of configurations (``--configs-per-shard``),
  grouped by configuration so train/test can be split by configuration.  Columns:
  ``config_id``, ``sample``, ``obs`` (float32 list), ``state`` (float64 list), ``risk``,
  ``min_risk_ctrl`` (list), ``min_risk_ctrl_dur``, ``n_leaves``; with ``--candidates`` also
  ``candidate_risk`` (list, one action-conditioned label per candidate control, see
  :meth:`rmm_envs.risk.RiskEstimator.estimate_candidates`; drawn after the plain labels, so
  ``risk`` is the same with or without candidates).
* ``manifest.json`` (written last): row count, per-shard SHA-256 and the dataset hash.
* ``shard-NNNNN.sha256`` (only while a run is unfinished): the SHA-256 of a shard, written
  right after the shard itself (``sha256sum -c`` format); folded into the manifest at the end.

Determinism: configuration ``c`` draws everything from ``SeedSequence(seed, spawn_key=(c, ...))``
so the same seed gives identical data whatever the worker count or backend.

Crash safety: each shard is written to a temporary file and renamed into place, so a shard is
either complete or absent.  Rerunning the same command (after Ctrl-C, ``kill -9`` or a crash)
checks the existing shards and computes only the missing ones; a directory made with other
parameters is refused rather than mixed.

Integrity: every shard's SHA-256 is recorded when it is written (its ``.sha256`` file, then
the manifest), and nothing else is ever trusted.  A rerun verifies every existing shard
against its recorded checksum and regenerates, with a line naming the file, any that does not
match or has no recorded checksum: generation is deterministic, so the result is exactly what
the damaged file held before.  The manifest is then built from the recorded checksums, never
from whatever the files hold now, so a damaged shard cannot be laundered into a valid-looking
dataset.  :func:`load_dataset` verifies every shard too and refuses a damaged dataset with
one line naming the file and the command that repairs it.

Backends: ``--backend local`` (processes, ``--workers`` default the core count) or
``--backend ray`` (``--ray-address`` of a cluster, else a local Ray; the optional extra
``rmm-envs[ray]``).  Ray tasks return their rows to this process, which writes the shards, so
no shared file system is needed.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

__all__ = ["DatagenConfig", "Dataset", "generate", "label_configs", "load_dataset", "main"]

FORMAT = "rmm-dataset"
FORMAT_VERSION = 1


@dataclass
class DatagenConfig:
    env_id: str = "Dubins4DCircles-v0"
    configs: int = 274
    samples_per_config: int = 128
    seed: int = 0
    branches: int = 32
    depth: int = 2
    horizon: float = 2.0
    n_steps: int = 8
    metric: str = "expected"
    alpha: float | None = None
    leaf: str = "zero"
    configs_per_shard: int = 8
    env_kwargs: dict = field(default_factory=dict)
    candidates: list | None = None  # action-conditioned labels: controls held for candidate_hold s
    candidate_hold: float = 1.0

    def validate(self) -> None:
        import rmm_envs
        from rmm_envs.risk.estimator import validate_tree_params

        if self.env_id not in rmm_envs.ENV_IDS:
            raise ValueError(f"unknown env {self.env_id!r}; expected one of {list(rmm_envs.ENV_IDS)}")
        for name in ("configs", "samples_per_config", "configs_per_shard"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed (--seed) must be an integer >= 0, got {self.seed!r}")
        validate_tree_params(**self.estimator_params())
        if self.candidates is not None:
            c = np.asarray(self.candidates, dtype=float)
            if c.ndim != 2 or c.shape[0] < 1 or not np.all(np.isfinite(c)):
                raise ValueError(f"candidates must be a non-empty list of finite controls, got {self.candidates!r}")
            if not (np.isfinite(self.candidate_hold) and self.candidate_hold > 0):
                raise ValueError(f"candidate_hold must be a finite number of seconds > 0, got {self.candidate_hold!r}")

    @property
    def n_shards(self) -> int:
        return -(-self.configs // self.configs_per_shard)

    def shard_configs(self, shard: int) -> range:
        lo = shard * self.configs_per_shard
        return range(lo, min(self.configs, lo + self.configs_per_shard))

    def estimator_params(self) -> dict:
        return {"branches": self.branches, "depth": self.depth, "horizon": self.horizon,
                "n_steps": self.n_steps, "metric": self.metric, "alpha": self.alpha, "leaf": self.leaf}


# ---------------------------------------------------------------------- labelling
_ENV_CACHE: dict = {}


def _env(cfg: DatagenConfig):
    key = (cfg.env_id, json.dumps(cfg.env_kwargs, sort_keys=True))
    if key not in _ENV_CACHE:
        import gymnasium as gym

        import rmm_envs  # noqa: F401

        _ENV_CACHE[key] = gym.make(cfg.env_id, **cfg.env_kwargs).unwrapped
    return _ENV_CACHE[key]


def config_seeds(seed: int, config_id: int) -> tuple[int, np.random.Generator]:
    """The env's reset seed and the sampling/labelling generator of one configuration."""
    env_seed = int(np.random.SeedSequence(seed, spawn_key=(config_id, 0)).generate_state(1)[0])
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(config_id, 1)))
    return env_seed, rng


def label_configs(cfg: DatagenConfig, config_ids) -> pa.Table:
    """Generate, observe and label the samples of the given configurations (Algorithm 2)."""
    from rmm_envs.risk.estimator import RiskEstimator

    env = _env(cfg)
    cols: dict[str, list] = {k: [] for k in ("config_id", "sample", "obs", "state", "risk", "min_risk_ctrl", "min_risk_ctrl_dur", "n_leaves")}
    for c in config_ids:
        env_seed, rng = config_seeds(cfg.seed, c)
        env.reset(seed=env_seed)
        states = env.sample_states(rng, cfg.samples_per_config)
        obs = env.observe_states(states, rng)
        est = RiskEstimator(env.risk_system(), **cfg.estimator_params())
        res = est.estimate(states, rng)
        n = states.shape[0]
        cols["config_id"].append(np.full(n, c, dtype=np.int32))
        cols["sample"].append(np.arange(n, dtype=np.int32))
        cols["obs"].append(obs.astype(np.float32))
        cols["state"].append(states.astype(np.float64))
        cols["risk"].append(res.risk)
        cols["min_risk_ctrl"].append(res.min_risk_ctrl)
        cols["min_risk_ctrl_dur"].append(res.min_risk_ctrl_dur)
        cols["n_leaves"].append(res.n_leaves.astype(np.int32))
        if cfg.candidates is not None:
            cols.setdefault("candidate_risk", []).append(est.estimate_candidates(states, cfg.candidates, cfg.candidate_hold, rng))
    arrays = {}
    for k, parts in cols.items():
        a = np.concatenate(parts)
        if a.ndim == 2:
            arrays[k] = pa.FixedSizeListArray.from_arrays(pa.array(a.reshape(-1)), a.shape[1])
        else:
            arrays[k] = pa.array(a)
    return pa.table(arrays)


# ---------------------------------------------------------------------- files
def _shard_path(out: Path, shard: int) -> Path:
    return out / f"shard-{shard:05d}.parquet"


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _checksum_path(shard_path: Path) -> Path:
    return shard_path.with_suffix(".sha256")


def _write_table(path: Path, table: pa.Table) -> None:
    """Write a shard atomically, then its checksum file (so a checksum file implies a whole shard)."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    data = sink.getvalue().to_pybytes()
    _atomic_write_bytes(path, data)
    _atomic_write_bytes(_checksum_path(path), f"{hashlib.sha256(data).hexdigest()}  {path.name}\n".encode())


def _recorded_checksum(shard_path: Path) -> str | None:
    """The checksum written next to a shard when it was written, if any."""
    try:
        digest = _checksum_path(shard_path).read_text().split()[0]
    except (OSError, IndexError, UnicodeDecodeError):
        return None
    return digest if len(digest) == 64 and all(c in "0123456789abcdef" for c in digest) else None


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _read_manifest_shards(out: Path) -> tuple[dict, str | None]:
    """``({shard name: sha256}, problem)`` from an existing manifest; empty if absent or unreadable."""
    path = out / "manifest.json"
    if not path.exists():
        return {}, None
    try:
        shards = json.loads(path.read_text())["shards"]
        if not isinstance(shards, dict):
            raise TypeError("'shards' is not a mapping")
        return {str(k): str(v) for k, v in shards.items()}, None
    except (OSError, ValueError, KeyError, TypeError) as e:
        return {}, f"{path} is unreadable ({type(e).__name__}: {e}); its checksums cannot be used"


def rerun_command(meta: dict, out) -> str:
    """The ``rmm-datagen`` command that (re)generates the dataset described by ``meta`` in ``out``."""
    est = meta.get("estimator") or {}
    parts = ["rmm-datagen", "--env", str(meta.get("env_id")), "--configs", str(meta.get("configs")),
             "--samples-per-config", str(meta.get("samples_per_config")), "--seed", str(meta.get("seed")),
             "--configs-per-shard", str(meta.get("configs_per_shard"))]
    for key, flag in (("branches", "--branches"), ("depth", "--depth"), ("horizon", "--horizon"),
                      ("n_steps", "--n-steps"), ("metric", "--metric"), ("alpha", "--alpha"), ("leaf", "--leaf")):
        if est.get(key) is not None:
            parts += [flag, str(est[key])]
    if meta.get("env_kwargs"):
        parts += ["--env-kwargs", json.dumps(meta["env_kwargs"], sort_keys=True)]
    return shlex.join(parts + ["--out", str(out)])


def _shard_ok(path: Path, rows: int) -> bool:
    try:
        return pq.read_metadata(path).num_rows == rows
    except Exception:
        return False


def _identity(meta: dict) -> dict:
    keys = ("format", "format_version", "env_id", "env_kwargs", "configs", "samples_per_config",
            "seed", "configs_per_shard", "estimator")
    return {k: meta.get(k) for k in keys}


def _metadata(cfg: DatagenConfig) -> dict:
    import rmm_envs

    env = _env(cfg)
    sys_ = env.risk_system() if getattr(env, "scene", None) is not None else None
    if sys_ is None:
        env.reset(seed=0)
        sys_ = env.risk_system()
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "env_id": cfg.env_id,
        "env_kwargs": cfg.env_kwargs,
        "configs": cfg.configs,
        "samples_per_config": cfg.samples_per_config,
        "seed": cfg.seed,
        "configs_per_shard": cfg.configs_per_shard,
        "estimator": cfg.estimator_params() | {"policy": "uniform"}
        | ({} if cfg.candidates is None else {"candidates": cfg.candidates, "candidate_hold": cfg.candidate_hold}),
        "obs_dim": int(env.observation_space.shape[0]),
        "state_dim": int(sys_.state_dim),
        "control_dim": int(sys_.control_dim),
        "obs_time_feature": "uniform over [0, max_episode_sim_time]" if cfg.env_id.startswith("Dubins4D") else None,
        "package_version": rmm_envs.__version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }


def _shard_task(cfg_dict: dict, out: str | None, shard: int):
    """Worker entry: label one shard; write it (local) or return its bytes (ray)."""
    cfg = DatagenConfig(**cfg_dict)
    t0 = time.perf_counter()
    table = label_configs(cfg, cfg.shard_configs(shard))
    if out is not None:
        _write_table(_shard_path(Path(out), shard), table)
        return shard, table.num_rows, time.perf_counter() - t0, None
    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, table.schema) as w:
        w.write_table(table)
    return shard, table.num_rows, time.perf_counter() - t0, sink.getvalue().to_pybytes()


def generate(cfg: DatagenConfig, out: str | os.PathLike, workers: int | None = None,
             backend: str = "local", ray_address: str | None = None, progress: bool = True) -> dict:
    """Generate (or finish) the dataset in ``out``; returns the manifest.

    Existing shards are kept only if they match the checksum recorded when they were written;
    the others are regenerated and listed in ``manifest["last_run"]["regenerated"]``.
    """
    cfg.validate()
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ValueError(f"workers (--workers) must be an integer >= 1 (leave it out for one per core), got {workers!r}")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    meta = _metadata(cfg)
    meta_path = out / "metadata.json"
    if meta_path.exists():
        try:
            old = json.loads(meta_path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ValueError(f"{meta_path} is unreadable ({e}); delete {out} or choose another --out") from None
        if _identity(old) != _identity(meta):
            diff = {k: (old.get(k), meta.get(k)) for k in _identity(meta) if old.get(k) != meta.get(k)}
            raise ValueError(
                f"{out} holds a dataset made with other parameters (existing vs requested: {diff}); "
                "choose another --out or delete it"
            )
    else:
        _atomic_write_bytes(meta_path, json.dumps(meta, indent=2).encode())
    for tmp in out.glob(".shard-*.tmp"):
        tmp.unlink(missing_ok=True)

    rows_of = {s: len(cfg.shard_configs(s)) * cfg.samples_per_config for s in range(cfg.n_shards)}
    in_manifest, manifest_problem = _read_manifest_shards(out)
    if manifest_problem:
        print(f"rmm-datagen: {manifest_problem}", file=sys.stderr)
    todo, regenerated, verified = [], [], {}
    for s in range(cfg.n_shards):
        p = _shard_path(out, s)
        if p.exists():
            expected = _recorded_checksum(p) or in_manifest.get(p.name)  # a checksum file is newer
            problem = None
            if expected is None:
                problem = "has no recorded checksum (written by an interrupted run or an older version)"
            elif _sha256_file(p) != expected:
                problem = "does not match the checksum recorded when it was written (damaged or changed since)"
            elif not _shard_ok(p, rows_of[s]):
                problem = f"does not hold the expected {rows_of[s]} rows"
            if problem is None:
                verified[p.name] = expected
                continue
            print(f"rmm-datagen: {p} {problem}; regenerating it", file=sys.stderr)
            regenerated.append(p.name)
        p.unlink(missing_ok=True)
        _checksum_path(p).unlink(missing_ok=True)
        todo.append(s)
    done_configs = cfg.configs - sum(len(cfg.shard_configs(s)) for s in todo)

    from tqdm import tqdm

    bar = tqdm(total=cfg.configs, initial=done_configs, unit="config", disable=not progress,
               desc=f"labelling {cfg.env_id}", dynamic_ncols=True)
    t0 = time.perf_counter()
    new_rows = 0
    try:
        if todo:
            if backend == "local":
                new_rows = _run_local(cfg, out, todo, workers, bar)
            elif backend == "ray":
                new_rows = _run_ray(cfg, out, todo, ray_address, bar)
            else:
                raise ValueError(f"unknown backend {backend!r}; expected 'local' or 'ray'")
    except KeyboardInterrupt:
        bar.close()
        left = sum(1 for s in range(cfg.n_shards) if not _shard_path(out, s).exists())
        print(f"\ninterrupted: {cfg.n_shards - left} of {cfg.n_shards} shards are saved in {out}; "
              "rerun the same command to finish", file=sys.stderr)
        raise
    bar.close()
    elapsed = time.perf_counter() - t0

    hashes = {}
    for s in range(cfg.n_shards):
        p = _shard_path(out, s)
        expected = verified.get(p.name) or _recorded_checksum(p)
        if not p.exists() or expected is None:
            raise RuntimeError(f"shard {p} is missing or has no checksum after generation; rerun the same command")
        if _sha256_file(p) != expected or not _shard_ok(p, rows_of[s]):
            raise RuntimeError(f"shard {p} changed while this run was writing the dataset; rerun the same command")
        hashes[p.name] = expected
    manifest = {
        "n_rows": sum(rows_of.values()),
        "n_shards": cfg.n_shards,
        "shards": hashes,
        "dataset_sha256": hashlib.sha256("".join(hashes[k] for k in sorted(hashes)).encode()).hexdigest(),
        "last_run": {"new_rows": new_rows, "seconds": elapsed, "backend": backend,
                     "labels_per_second": new_rows / elapsed if elapsed > 0 and new_rows else None,
                     "regenerated": regenerated},
    }
    _atomic_write_bytes(out / "manifest.json", json.dumps(manifest, indent=2).encode())
    for s in range(cfg.n_shards):  # the manifest holds the checksums now
        _checksum_path(_shard_path(out, s)).unlink(missing_ok=True)
    return manifest


def _shard_job(job):
    """Worker entry for :func:`rmm_envs.parallel.run_local` / ``run_ray``: ``job`` is ``(config dict, out or None, shard)``."""
    return _shard_task(*job)


# Stop after this many shards in a row lost their worker with none finishing: a cause that
# kills every worker (too little memory for one shard) then ends the run instead of starting
# a fresh worker for every remaining shard.
_MAX_LOST_IN_A_ROW = 3


def _lost_shards_error(lost: list, todo: list[int], out: Path, stopped: str | None = None) -> RuntimeError:
    what = "; ".join(f"shard {shard} ({cause})" for shard, cause in lost[:5]) + (f"; and {len(lost) - 5} more" if len(lost) > 5 else "")
    head = f"{stopped}; " if stopped else ""
    return RuntimeError(f"{head}{len(lost)} of {len(todo)} shards to compute were lost: {what}. The finished shards are saved "
                        f"in {out}; rerun the same command to compute the missing ones (fewer --workers if memory ran out)")


def _collect(cfg: DatagenConfig, out: Path, todo: list[int], results, bar) -> int:
    """Count the rows of finished shards (writing those that came back as bytes, from Ray);
    a shard whose worker was lost is reported after the others finish."""
    from rmm_envs.parallel import TaskLost, WorkersLost

    rows = 0
    lost: list = []
    try:
        for res in results:
            if isinstance(res, TaskLost):
                lost.append((res.task[2], res.cause))
                continue
            shard, n, _, payload = res
            if payload is not None:
                _write_table(_shard_path(out, shard), pa.ipc.open_stream(payload).read_all())
            rows += n
            bar.update(len(cfg.shard_configs(shard)))
    except WorkersLost as e:
        raise _lost_shards_error(lost, todo, out, str(e)) from None
    if lost:
        raise _lost_shards_error(lost, todo, out)
    return rows


def _run_local(cfg: DatagenConfig, out: Path, todo: list[int], workers: int | None, bar) -> int:
    """Label the ``todo`` shards on local processes; a shard whose worker dies is reported, the rest finish."""
    from rmm_envs.parallel import run_local

    if workers is None:
        workers = os.cpu_count() or 1  # generate() has refused anything but an integer >= 1
    jobs = [(asdict(cfg), str(out), s) for s in todo]
    return _collect(cfg, out, todo, run_local(_shard_job, jobs, workers, max_lost_in_a_row=_MAX_LOST_IN_A_ROW), bar)


def _run_ray(cfg: DatagenConfig, out: Path, todo: list[int], address: str | None, bar) -> int:
    """Label the ``todo`` shards as Ray tasks and write them here; a shard Ray loses is reported."""
    from rmm_envs.parallel import run_ray

    jobs = [(asdict(cfg), None, s) for s in todo]
    return _collect(cfg, out, todo, run_ray(_shard_job, jobs, address, max_lost_in_a_row=_MAX_LOST_IN_A_ROW), bar)


# ---------------------------------------------------------------------- loading
@dataclass
class Dataset:
    obs: np.ndarray
    state: np.ndarray
    risk: np.ndarray
    min_risk_ctrl: np.ndarray
    min_risk_ctrl_dur: np.ndarray
    n_leaves: np.ndarray
    config_id: np.ndarray
    meta: dict
    sha256: str
    candidate_risk: np.ndarray | None = None  # (N, K) with --candidates, else None

    def __len__(self) -> int:
        return self.risk.shape[0]

    def to_pandas(self, vectors: str = "columns"):
        """The dataset as a ``pandas.DataFrame``, one row per labelled state, in file order.

        Columns: ``config_id``, ``risk``, ``min_risk_ctrl_dur``, ``n_leaves``, then the vector
        fields ``obs`` (17 float32 values for Dubins4D), ``state`` and ``min_risk_ctrl``:

        * ``vectors="columns"`` (the default: what filtering and plotting want): one column per
          element, ``obs_0 ... obs_16``, ``state_0 ...``, ``min_risk_ctrl_0, min_risk_ctrl_1``,
          keeping the arrays' dtypes;
        * ``vectors="lists"``: one column per field whose cells are 1-D numpy arrays (as the
          Parquet shards store them).

        ``df.attrs`` holds ``meta`` (the dataset's metadata) and ``sha256`` (its hash).
        """
        import pandas as pd

        if vectors not in ("columns", "lists"):
            raise ValueError(f"vectors must be 'columns' or 'lists', got {vectors!r}")
        data: dict = {"config_id": self.config_id, "risk": self.risk, "min_risk_ctrl_dur": self.min_risk_ctrl_dur,
                      "n_leaves": self.n_leaves}
        for name in ("obs", "state", "min_risk_ctrl"):
            arr = getattr(self, name)
            if vectors == "columns":
                data.update({f"{name}_{j}": arr[:, j] for j in range(arr.shape[1])})
            else:
                data[name] = list(arr)
        df = pd.DataFrame(data)
        df.attrs.update(meta=self.meta, sha256=self.sha256)
        return df


def _fixed_list(col: pa.ChunkedArray, name: str, path: Path) -> np.ndarray:
    arr = col.combine_chunks()
    if not pa.types.is_fixed_size_list(arr.type):
        raise ValueError(f"{path}: column {name!r} should be a fixed-size list, got {arr.type}")
    return np.asarray(arr.values.to_numpy(zero_copy_only=False)).reshape(len(arr), arr.type.list_size)


def load_dataset(path: str | os.PathLike) -> Dataset:
    """Load a dataset directory written by ``rmm-datagen``, checking its files on the way.

    Every shard must match the SHA-256 the manifest recorded when it was written, and the
    manifest must list exactly the shards the metadata implies.  Any problem raises
    ``ValueError`` with one line naming the file and the command that repairs it.
    """
    path = Path(path)
    meta_path = path / "metadata.json"
    if not meta_path.exists():
        raise FileNotFoundError(f"{path} is not an rmm-datagen dataset: {meta_path} is missing")
    try:
        meta = json.loads(meta_path.read_text())
        if not isinstance(meta, dict):
            raise ValueError("not a JSON object")
    except (OSError, UnicodeDecodeError, ValueError) as e:
        raise ValueError(f"{meta_path} is unreadable or not valid JSON ({e}): the dataset cannot be identified; "
                         f"move {path} aside and generate it again with rmm-datagen") from None
    if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(f"{meta_path}: expected format {FORMAT} v{FORMAT_VERSION}, got {meta.get('format')} v{meta.get('format_version')}")
    repair = f"rerun `{rerun_command(meta, path)}` to regenerate what is damaged or missing"
    manifest_path = path / "manifest.json"
    if not manifest_path.exists():
        raise ValueError(f"{path} is incomplete (no manifest.json): {repair}")
    try:
        manifest = json.loads(manifest_path.read_text())
        shards = manifest["shards"]
        if not isinstance(shards, dict):
            raise TypeError("'shards' is not a mapping")
        dataset_sha = str(manifest["dataset_sha256"])
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as e:
        raise ValueError(f"{manifest_path} is unreadable ({type(e).__name__}: {e}): {repair}") from None
    try:
        expected_names = {_shard_path(path, s).name for s in range(-(-int(meta["configs"]) // int(meta["configs_per_shard"])))}
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        expected_names = None
    if expected_names is not None and set(shards) != expected_names:
        missing = sorted(expected_names - set(shards))
        raise ValueError(f"{manifest_path} does not list the shards {meta_path.name} implies "
                         f"(missing {missing[:3]}{'...' if len(missing) > 3 else ''}, "
                         f"unexpected {sorted(set(shards) - expected_names)[:3]}): {repair}")
    parts = []
    for name in sorted(shards):
        p = path / name
        if not p.exists():
            raise ValueError(f"{p} is listed in the manifest but missing: {repair}")
        data = p.read_bytes()
        if hashlib.sha256(data).hexdigest() != shards[name]:
            raise ValueError(f"{p} does not match its checksum in the manifest (damaged or changed after generation): {repair}")
        try:
            parts.append(pq.read_table(pa.BufferReader(data)))
        except (pa.ArrowException, OSError, ValueError) as e:
            raise ValueError(f"{p} cannot be read ({e}): {repair}") from None
    if not parts:
        raise ValueError(f"{path} holds no shards")
    t = pa.concat_tables(parts)
    obs = _fixed_list(t["obs"], "obs", path).astype(np.float32)
    if obs.shape[1] != meta["obs_dim"]:
        raise ValueError(f"{path}: observations have {obs.shape[1]} features, metadata says {meta['obs_dim']}")
    return Dataset(
        obs=obs,
        state=_fixed_list(t["state"], "state", path),
        risk=t["risk"].to_numpy(),
        min_risk_ctrl=_fixed_list(t["min_risk_ctrl"], "min_risk_ctrl", path),
        min_risk_ctrl_dur=t["min_risk_ctrl_dur"].to_numpy(),
        n_leaves=t["n_leaves"].to_numpy(),
        config_id=t["config_id"].to_numpy(),
        meta=meta,
        sha256=dataset_sha,
        candidate_risk=_fixed_list(t["candidate_risk"], "candidate_risk", path) if "candidate_risk" in t.column_names else None,
    )


# ---------------------------------------------------------------------- CLI
def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-datagen",
        description="Generate a risk-labelled dataset (Algorithm 2): obstacle configurations, "
        "valid states, their observations and sampling-tree risk labels, written as Parquet shards. "
        "Rerun the same command to resume an interrupted run.",
    )
    p.add_argument("--env", default="Dubins4DCircles-v0", help="environment id (default: %(default)s)")
    p.add_argument("--configs", type=int, default=274, help="number of obstacle configurations (default: %(default)s)")
    p.add_argument("--samples-per-config", type=int, default=128, help="labelled states per configuration (default: %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="master seed (default: %(default)s)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--branches", type=int, default=32, help="tree branching factor n (default: %(default)s)")
    p.add_argument("--depth", type=int, default=2, help="tree depth m (default: %(default)s)")
    p.add_argument("--horizon", type=float, default=2.0, help="seconds per tree level t (default: %(default)s)")
    p.add_argument("--n-steps", type=int, default=8, help="path points per branch (default: %(default)s)")
    p.add_argument("--metric", default="expected", choices=["expected", "cvar", "worst"], help="coherent risk metric (default: %(default)s)")
    p.add_argument("--alpha", type=float, default=None, help="CVaR level in (0, 1) (with --metric cvar)")
    p.add_argument("--leaf", default="zero", choices=["zero", "heuristic"], help="leaf value: 0 (Algorithm 1) or the system's heuristic (default: %(default)s)")
    p.add_argument("--env-kwargs", default="{}", help='environment arguments as JSON, e.g. \'{"maze_kind": "mixed"}\' (default: {})')
    p.add_argument("--candidates", default=None,
                   help="also label the risk of holding each of these controls for --candidate-hold s, then the tree, "
                   "as JSON, e.g. '[[-0.25, -0.5], [0.25, -0.5]]' (default: none)")
    p.add_argument("--candidate-hold", type=float, default=1.0, help="seconds each candidate is held (default: %(default)s)")
    p.add_argument("--configs-per-shard", type=int, default=8, help="configurations per output shard (default: %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="worker processes, >= 1 (default: the core count)")
    p.add_argument("--backend", default="local", choices=["local", "ray"], help="where the work runs (default: %(default)s)")
    p.add_argument("--ray-address", default=None, help="Ray cluster address (with --backend ray; default: a local Ray)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        env_kwargs = json.loads(args.env_kwargs)
        if not isinstance(env_kwargs, dict):
            raise ValueError
    except ValueError:
        print(f"rmm-datagen: error: --env-kwargs must be a JSON object, got {args.env_kwargs!r}", file=sys.stderr)
        return 2
    try:
        candidates = None if args.candidates is None else json.loads(args.candidates)
        if candidates is not None and not (isinstance(candidates, list) and all(isinstance(c, list) for c in candidates)):
            raise ValueError
    except ValueError:
        print(f"rmm-datagen: error: --candidates must be a JSON list of controls, got {args.candidates!r}", file=sys.stderr)
        return 2
    cfg = DatagenConfig(
        env_id=args.env, configs=args.configs, samples_per_config=args.samples_per_config, seed=args.seed,
        branches=args.branches, depth=args.depth, horizon=args.horizon, n_steps=args.n_steps,
        metric=args.metric, alpha=args.alpha, leaf=args.leaf, configs_per_shard=args.configs_per_shard,
        env_kwargs=env_kwargs, candidates=candidates, candidate_hold=args.candidate_hold,
    )
    try:
        manifest = generate(cfg, args.out, workers=args.workers, backend=args.backend,
                            ray_address=args.ray_address, progress=not args.no_progress)
    except KeyboardInterrupt:
        return 130
    except (ValueError, RuntimeError, FileNotFoundError) as e:
        print(f"rmm-datagen: error: {e}", file=sys.stderr)
        return 2
    run = manifest["last_run"]
    rate = f", {run['labels_per_second']:.0f} labels/s" if run["labels_per_second"] else ""
    print(f"{manifest['n_rows']} labelled samples in {args.out} ({manifest['n_shards']} shards); "
          f"this run: {run['new_rows']} new in {run['seconds']:.1f} s{rate}; dataset sha256 {manifest['dataset_sha256'][:16]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
