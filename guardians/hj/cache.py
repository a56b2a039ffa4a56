"""On-disk cache of solved value functions, keyed by a hash of everything that determines them.

Files are raw float32 ``.npy`` arrays (17 MB on the default grid) named by the SHA-256 of
``{dynamics, grid, horizon, scheme, obstacles}``; written atomically; the oldest files beyond
``max_files`` are removed.  Several processes may share a directory (the benchmark's workers
do): a file another process removes at any moment is a cache miss, never an error.

The directory is the HJ guardian's ``cache_dir`` argument; without one,
:func:`default_cache_dir`: ``$RMM_HJ_CACHE`` if set (the one place it is read), else
``~/.cache/rmm-envs/hj`` (a per-user cache outside any checkout).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import warnings
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["ValueCache", "default_cache_dir", "load_or_solve"]


def load_or_solve(cache: "ValueCache | None", spec: dict, shape, solve: Callable[[], np.ndarray],
                  counts: dict) -> tuple[np.ndarray, float | None]:
    """The value function that ``spec`` determines: read from ``cache`` when it holds it
    (``counts["cache_hits"]`` += 1), else ``solve()`` (``counts["solves"]`` += 1) and saved there.
    A cache that cannot be written is an optimisation lost, not an error: it is counted
    (``counts["cache_errors"]``) and warned about.  ``cache=None``: always solve.  Returns
    ``(V, seconds the solve took)``, the seconds ``None`` on a cache hit."""
    key = ValueCache.key(spec) if cache is not None else None
    V = cache.load(key, shape) if cache is not None else None
    if V is not None:
        counts["cache_hits"] += 1
        return V, None
    t0 = time.perf_counter()
    V = solve()
    seconds = time.perf_counter() - t0
    counts["solves"] += 1
    if cache is not None:
        try:
            cache.save(key, V)
        except OSError as e:  # a full disk must not end the episode
            counts["cache_errors"] = counts.get("cache_errors", 0) + 1
            warnings.warn(f"HJ value cache not written ({e}); continuing without it", RuntimeWarning, stacklevel=3)
    return V, seconds


def default_cache_dir() -> Path:
    """``$RMM_HJ_CACHE`` if set, else ``~/.cache/rmm-envs/hj``."""
    return Path(os.environ.get("RMM_HJ_CACHE") or Path.home() / ".cache" / "rmm-envs" / "hj")


class ValueCache:
    def __init__(self, directory: str | Path | None = None, max_files: int = 64) -> None:
        self.dir = Path(directory) if directory is not None else default_cache_dir()
        self.max_files = int(max_files)

    @staticmethod
    def key(spec: dict) -> str:
        return hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()

    def path(self, key: str) -> Path:
        return self.dir / f"{key}.npy"

    def load(self, key: str, shape) -> np.ndarray | None:
        p = self.path(key)
        if not p.exists():
            return None
        try:
            V = np.load(p, allow_pickle=False)
        except (ValueError, OSError, EOFError):
            p.unlink(missing_ok=True)  # a damaged entry is recomputed
            return None
        if V.shape != tuple(shape) or V.dtype != np.float32:
            p.unlink(missing_ok=True)
            return None
        try:
            os.utime(p)  # most recently used
        except OSError:  # evicted by another process meanwhile: the loaded array is still good
            pass
        return V

    def save(self, key: str, V: np.ndarray) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        p = self.path(key)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        with open(tmp, "wb") as fh:
            np.save(fh, V.astype(np.float32, copy=False), allow_pickle=False)
        os.replace(tmp, p)
        self._evict()

    def _evict(self) -> None:
        """Remove the least recently used files beyond ``max_files``, tolerating files that
        other processes remove concurrently."""
        aged = []
        for f in self.dir.glob("*.npy"):
            try:
                aged.append((f.stat().st_mtime, f))
            except FileNotFoundError:
                continue
        aged.sort()
        for _, f in aged[: max(0, len(aged) - self.max_files)]:
            f.unlink(missing_ok=True)
