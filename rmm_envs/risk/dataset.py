"""A dataset directory of ``rmm-datagen``: its files, how they are written atomically and
checked, and :func:`load_dataset`, which reads and verifies one.

The layout (``metadata.json``, ``shard-NNNNN.parquet``, ``shard-NNNNN.sha256`` while a run is
unfinished, ``manifest.json`` last) and the integrity rules are described in
:mod:`rmm_envs.risk.datagen`.
"""

from __future__ import annotations

import hashlib
import json
import os
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from rmm_envs.catalog import current_id

__all__ = ["FORMAT", "FORMAT_VERSION", "Dataset", "load_dataset", "rerun_command"]

FORMAT = "rmm-dataset"
FORMAT_VERSION = 1


def shard_path(out: Path, shard: int) -> Path:
    return out / f"shard-{shard:05d}.parquet"


def atomic_write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as fh:
        fh.write(data)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def checksum_path(shard_path: Path) -> Path:
    return shard_path.with_suffix(".sha256")


def write_table(path: Path, table: pa.Table) -> None:
    """Write a shard atomically, then its checksum file (so a checksum file implies a whole shard)."""
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    data = sink.getvalue().to_pybytes()
    atomic_write_bytes(path, data)
    atomic_write_bytes(checksum_path(path), f"{hashlib.sha256(data).hexdigest()}  {path.name}\n".encode())


def recorded_checksum(shard_path: Path) -> str | None:
    """The checksum written next to a shard when it was written, if any."""
    try:
        digest = checksum_path(shard_path).read_text().split()[0]
    except (OSError, IndexError, UnicodeDecodeError):
        return None
    return digest if len(digest) == 64 and all(c in "0123456789abcdef" for c in digest) else None


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def read_manifest_shards(out: Path) -> tuple[dict, str | None]:
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
    parts = [
        "rmm-datagen",
        "--env",
        str(meta.get("env_id")),
        "--configs",
        str(meta.get("configs")),
        "--samples-per-config",
        str(meta.get("samples_per_config")),
        "--seed",
        str(meta.get("seed")),
        "--configs-per-shard",
        str(meta.get("configs_per_shard")),
    ]
    for key, flag in (
        ("branches", "--branches"),
        ("depth", "--depth"),
        ("horizon", "--horizon"),
        ("n_steps", "--n-steps"),
        ("metric", "--metric"),
        ("alpha", "--alpha"),
        ("leaf", "--leaf"),
    ):
        if est.get(key) is not None:
            parts += [flag, str(est[key])]
    for key, value in sorted((meta.get("env_kwargs") or {}).items()):
        parts += ["--env-opt", f"{key}={json.dumps(value)}"]
    return shlex.join(parts + ["--out", str(out)])


def shard_ok(path: Path, rows: int) -> bool:
    try:
        return pq.read_metadata(path).num_rows == rows
    except Exception:
        return False


def identity(meta: dict) -> dict:
    """What makes two datasets the same dataset; a former env id counts as today's id, so a dataset
    made under a former id (:data:`rmm_envs.catalog.FORMER_IDS`) is resumed under today's."""
    keys = (
        "format",
        "format_version",
        "env_id",
        "env_kwargs",
        "configs",
        "samples_per_config",
        "seed",
        "configs_per_shard",
        "estimator",
        "failure",
    )
    out = {k: meta.get(k) for k in keys}
    if isinstance(out["env_id"], str):
        out["env_id"] = current_id(out["env_id"])
    return out


def prepare_folder(out: Path, meta: dict) -> None:
    """Write ``metadata.json`` into ``out``, or check that the one there describes the same dataset
    (``ValueError`` naming what differs); remove temporary shards an interrupted run left."""
    meta_path = out / "metadata.json"
    if meta_path.exists():
        try:
            old = json.loads(meta_path.read_text())
        except (OSError, json.JSONDecodeError) as e:
            raise ValueError(f"{meta_path} is unreadable ({e}); delete {out} or choose another --out") from None
        if identity(old) != identity(meta):
            diff = {k: (old.get(k), meta.get(k)) for k in identity(meta) if old.get(k) != meta.get(k)}
            raise ValueError(
                f"{out} holds a dataset made with other parameters (existing vs requested: {diff}); "
                "choose another --out or delete it"
            )
    else:
        atomic_write_bytes(meta_path, json.dumps(meta, indent=2).encode())
    for tmp in out.glob(".shard-*.tmp"):
        tmp.unlink(missing_ok=True)


def shards_to_label(out: Path, rows_of: dict[int, int]) -> tuple[list[int], list[str], dict[str, str]]:
    """``(todo, regenerated, verified)`` of a dataset folder whose shard ``s`` holds ``rows_of[s]``
    rows: the shards to (re)compute (a shard that is kept matches the checksum recorded when it was
    written and its row count; any other is removed, and named on stderr when it existed), the
    names of those regenerated and ``{name: sha256}`` of those kept."""
    in_manifest, manifest_problem = read_manifest_shards(out)
    if manifest_problem:
        print(f"rmm-datagen: {manifest_problem}", file=sys.stderr)
    todo: list[int] = []
    regenerated: list[str] = []
    verified: dict[str, str] = {}
    for s in range(len(rows_of)):
        p = shard_path(out, s)
        if p.exists():
            expected = recorded_checksum(p) or in_manifest.get(p.name)  # a checksum file is newer
            problem = None
            if expected is None:
                problem = "has no recorded checksum (written by an interrupted run or an older version)"
            elif sha256_file(p) != expected:
                problem = "does not match the checksum recorded when it was written (damaged or changed since)"
            elif not shard_ok(p, rows_of[s]):
                problem = f"does not hold the expected {rows_of[s]} rows"
            if problem is None and expected is not None:
                verified[p.name] = expected
                continue
            print(f"rmm-datagen: {p} {problem}; regenerating it", file=sys.stderr)
            regenerated.append(p.name)
        p.unlink(missing_ok=True)
        checksum_path(p).unlink(missing_ok=True)
        todo.append(s)
    return todo, regenerated, verified


def write_manifest(out: Path, rows_of: dict[int, int], verified: dict[str, str], last_run: dict) -> dict:
    """Check every shard against its recorded checksum and row count (``RuntimeError`` naming one
    missing or changed), write ``manifest.json`` from the recorded checksums (never from what the
    files hold now), remove the checksum files it replaces, and return it."""
    hashes = {}
    for s in range(len(rows_of)):
        p = shard_path(out, s)
        expected = verified.get(p.name) or recorded_checksum(p)
        if not p.exists() or expected is None:
            raise RuntimeError(f"shard {p} is missing or has no checksum after generation; rerun the same command")
        if sha256_file(p) != expected or not shard_ok(p, rows_of[s]):
            raise RuntimeError(f"shard {p} changed while this run was writing the dataset; rerun the same command")
        hashes[p.name] = expected
    manifest = {
        "n_rows": sum(rows_of.values()),
        "n_shards": len(rows_of),
        "shards": hashes,
        "dataset_sha256": hashlib.sha256("".join(hashes[k] for k in sorted(hashes)).encode()).hexdigest(),
        "last_run": last_run,
    }
    atomic_write_bytes(out / "manifest.json", json.dumps(manifest, indent=2).encode())
    for s in range(len(rows_of)):  # the manifest holds the checksums now
        checksum_path(shard_path(out, s)).unlink(missing_ok=True)
    return manifest


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
        import pandas as pd  # lazy: heavy (about 0.3 s to import), read by this method only

        if vectors not in ("columns", "lists"):
            raise ValueError(f"vectors must be 'columns' or 'lists', got {vectors!r}")
        data: dict = {
            "config_id": self.config_id,
            "risk": self.risk,
            "min_risk_ctrl_dur": self.min_risk_ctrl_dur,
            "n_leaves": self.n_leaves,
        }
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
        raise ValueError(
            f"{meta_path} is unreadable or not valid JSON ({e}): the dataset cannot be identified; "
            f"move {path} aside and generate it again with rmm-datagen"
        ) from None
    if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{meta_path}: expected format {FORMAT} v{FORMAT_VERSION}, got {meta.get('format')} v{meta.get('format_version')}"
        )
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
        expected_names = {
            shard_path(path, s).name for s in range(-(-int(meta["configs"]) // int(meta["configs_per_shard"])))
        }
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        expected_names = None
    if expected_names is not None and set(shards) != expected_names:
        missing = sorted(expected_names - set(shards))
        raise ValueError(
            f"{manifest_path} does not list the shards {meta_path.name} implies "
            f"(missing {missing[:3]}{'...' if len(missing) > 3 else ''}, "
            f"unexpected {sorted(set(shards) - expected_names)[:3]}): {repair}"
        )
    parts = []
    for name in sorted(shards):
        p = path / name
        if not p.exists():
            raise ValueError(f"{p} is listed in the manifest but missing: {repair}")
        data = p.read_bytes()
        if hashlib.sha256(data).hexdigest() != shards[name]:
            raise ValueError(
                f"{p} does not match its checksum in the manifest (damaged or changed after generation): {repair}"
            )
        try:
            parts.append(pq.read_table(pa.BufferReader(data)))
        except (pa.ArrowException, OSError, ValueError) as e:
            raise ValueError(f"{p} cannot be read ({e}): {repair}") from None
    if not parts:
        raise ValueError(f"{path} holds no shards")
    try:
        t = pa.concat_tables(parts)
    except pa.ArrowInvalid as e:  # shards written by different versions: pyarrow's message is many lines
        raise ValueError(
            f"{path}: the shards do not share one schema ({str(e).splitlines()[0].strip()}): {repair}"
        ) from None
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
        candidate_risk=_fixed_list(t["candidate_risk"], "candidate_risk", path)
        if "candidate_risk" in t.column_names
        else None,
    )
