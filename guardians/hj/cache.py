"""On-disk cache of solved value functions, keyed by a hash of everything that determines them.

Each entry is one uncompressed ``.npz`` file named by the SHA-256 of its solve parameters
``{dynamics, grid, horizon, scheme, obstacles}`` (the ``spec``), holding the float32 value
``V`` and ``meta`` (the ``spec`` and the SHA-256 of ``V``).  An entry is used only if it is
verified; anything else is recomputed and replaced, with a ``RuntimeWarning`` naming the file
(counted in ``counts["cache_rejected"]``).  Written atomically; the oldest files beyond
``max_files`` are removed; several processes may share a directory.  The directory is the HJ
guardian's ``cache_dir`` argument; without one, :func:`default_cache_dir`: ``$RMM_HJ_CACHE`` if
set (read by :mod:`rmm_envs.environment_variables`), else ``~/.cache/rmm-envs/hj``.

What is verified and what sharing a directory means: :class:`ValueCache`.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from rmm_envs.environment_variables import hj_cache_dir

__all__ = ["CacheEntryRejected", "ValueCache", "default_cache_dir", "load_or_solve"]

FORMAT = "rmm-hj-value"


class CacheEntryRejected(Exception):
    """A cache entry exists but is not the verified value of the parameters asked for."""


def _digest(V: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(V, dtype=np.float32).tobytes()).hexdigest()


def load_or_solve(
    cache: ValueCache | None, spec: dict, shape, solve: Callable[[], np.ndarray], counts: dict
) -> tuple[np.ndarray, float | None]:
    """The value function that ``spec`` determines: read from ``cache`` when it holds it
    (``counts["cache_hits"]`` += 1), else ``solve()`` (``counts["solves"]`` += 1) and saved there.
    A cache that cannot be written is an optimisation lost, not an error: it is counted
    (``counts["cache_errors"]``) and warned about.  ``cache=None``: always solve.  Returns
    ``(V, seconds the solve took)``, the seconds ``None`` on a cache hit."""
    V = None
    if cache is not None:
        key = ValueCache.key(spec)  # the entry's name (the save below uses it too)
        try:
            V = cache.load(key, shape, spec)
        except CacheEntryRejected as e:
            counts["cache_rejected"] = counts.get("cache_rejected", 0) + 1
            warnings.warn(f"{e}; recomputing it", RuntimeWarning, stacklevel=3)
    if V is not None:
        counts["cache_hits"] += 1
        return V, None
    t0 = time.perf_counter()
    V = solve()
    seconds = time.perf_counter() - t0
    counts["solves"] += 1
    if cache is not None:
        try:
            cache.save(key, V, spec)
        except OSError as e:  # a full disk must not end the episode
            counts["cache_errors"] = counts.get("cache_errors", 0) + 1
            warnings.warn(f"HJ value cache not written ({e}); continuing without it", RuntimeWarning, stacklevel=3)
    return V, seconds


def default_cache_dir() -> Path:
    """``$RMM_HJ_CACHE`` if set, else ``~/.cache/rmm-envs/hj`` (read by :mod:`rmm_envs.environment_variables`)."""
    return hj_cache_dir()


class ValueCache:
    """The cache in ``directory`` (``None``: :func:`default_cache_dir`), at most ``max_files``.

    An entry is used only if it is verified: its stored ``spec`` equals the one asked for and its
    array has the recorded shape and SHA-256.  Anything else (a damaged or edited file, an array
    overwritten with another of the same shape, an entry of another solve, a file of the older raw
    ``.npy`` format) is recomputed and replaced, said once with a ``RuntimeWarning`` naming the
    file and counted (``counts["cache_rejected"]``, which the HJ guardians report in their stats).
    Entries are written atomically, and the oldest files beyond ``max_files`` removed.  Several
    processes may share a directory (the benchmark's workers do): a file another process removes
    at any moment is a cache miss, never an error."""

    def __init__(self, directory: str | Path | None = None, max_files: int = 64) -> None:
        self.dir = Path(directory) if directory is not None else default_cache_dir()
        self.max_files = int(max_files)

    @staticmethod
    def key(spec: dict) -> str:
        return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.npz"

    def load(self, key: str, shape, spec: dict | None = None) -> np.ndarray | None:
        """The verified value stored under ``key``; None if there is none.  Raises
        :class:`CacheEntryRejected` (naming the file and the reason) for an entry that is damaged,
        fails its checksum, has another shape or was solved for other parameters than ``spec``
        (when given); the entry is removed."""
        p = self.path(key)
        if not p.exists():
            return None
        try:
            problem, V = self._verified(p, shape, spec)
        except FileNotFoundError:  # evicted by another process meanwhile: a miss
            return None
        if problem:
            p.unlink(missing_ok=True)
            raise CacheEntryRejected(f"HJ value cache entry {p} {problem}")
        try:
            os.utime(p)  # most recently used
        except OSError:  # evicted by another process meanwhile: the loaded array is still good
            pass
        return V

    @staticmethod
    def _verified(p: Path, shape, spec: dict | None) -> tuple[str | None, np.ndarray | None]:
        unverified = "is not a verified entry (no recorded parameters and checksum)"
        try:
            z = np.load(p, allow_pickle=False)
            if not isinstance(z, np.lib.npyio.NpzFile):  # a bare array (.npy) under the entry's name
                return unverified, None
            with z:
                if set(z.files) != {"V", "meta"}:
                    return unverified, None
                V = z["V"]
                meta = json.loads(z["meta"].tobytes().decode())
        except FileNotFoundError:
            raise
        except (ValueError, OSError, EOFError, UnicodeDecodeError) as e:
            return f"cannot be read ({type(e).__name__}: {e})", None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            return "is not a verified entry (no recorded parameters and checksum)", None
        if spec is not None and meta.get("spec") != json.loads(json.dumps(spec, sort_keys=True)):
            return "was solved for other parameters than its name says", None
        if V.dtype != np.float32 or V.shape != tuple(shape) or list(V.shape) != meta.get("shape"):
            return f"holds an array of shape {V.shape} ({V.dtype}), expected {tuple(shape)} float32", None
        if _digest(V) != meta.get("sha256"):
            return "does not match its recorded checksum (damaged or edited)", None
        return None, V

    def save(self, key: str, V: np.ndarray, spec: dict | None = None) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        p = self.path(key)
        V = np.ascontiguousarray(V, dtype=np.float32)
        meta = {"format": FORMAT, "spec": spec, "shape": list(V.shape), "sha256": _digest(V)}
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            np.savez(fh, V=V, meta=np.frombuffer(json.dumps(meta, sort_keys=True).encode(), dtype=np.uint8))
        os.replace(tmp, p)
        self._evict()

    def _evict(self) -> None:
        """Remove the least recently used files beyond ``max_files``, tolerating files that
        other processes remove concurrently."""
        aged = []
        for f in [*self.dir.glob("*.npz"), *self.dir.glob("*.npy")]:  # .npy: entries of the older, unverified format
            try:
                aged.append((f.stat().st_mtime, f))
            except FileNotFoundError:
                continue
        aged.sort()
        for _, f in aged[: max(0, len(aged) - self.max_files)]:
            f.unlink(missing_ok=True)
