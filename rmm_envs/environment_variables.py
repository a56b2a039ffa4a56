"""The environment variables the project reads, and the one place each is read.

===================== =====================================================================
``RMM_HJ_THREADS``    threads of the HJ guardians' compiled solve when none is given
                      (an integer >= 1; unset: numba's default, the core count)
``RMM_HJ_CACHE``      folder of the HJ value-function cache (unset: ``~/.cache/rmm-envs/hj``)
``RMM_REFERENCE_DIR`` folder of reference results for ``rmm-bench compare --reference``
                      (unset: the ones shipped in ``rmm_bench/reference``)
===================== =====================================================================

Everything else is an argument.  ``tests/test_layers.py`` fails if another module of the
package reads ``os.environ`` (``benchmarks/arith.py`` builds its children's environment and is
the one exception: it passes variables on, it does not read a setting).  :func:`safe_path_start`
sets Python's own ``PYTHONSAFEPATH`` while a worker process starts (:mod:`rmm_envs.pool`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

__all__ = [
    "HJ_CACHE",
    "HJ_THREADS",
    "REFERENCE_DIR",
    "VARIABLES",
    "hj_cache_dir",
    "hj_threads",
    "reference_dir",
    "safe_path_started",
    "safe_path_start",
]

HJ_THREADS = "RMM_HJ_THREADS"
HJ_CACHE = "RMM_HJ_CACHE"
REFERENCE_DIR = "RMM_REFERENCE_DIR"
#: every variable read here, with what it sets
VARIABLES = {
    HJ_THREADS: "threads of the HJ guardians' compiled solve",
    HJ_CACHE: "folder of the HJ value cache",
    REFERENCE_DIR: "folder of the reference results rmm-bench compare --reference reads",
}


def hj_threads() -> int | None:
    """``$RMM_HJ_THREADS`` as an integer >= 1, or ``None`` when unset or empty; ``ValueError``
    naming the value otherwise."""
    raw = os.environ.get(HJ_THREADS)
    if not raw:
        return None
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{HJ_THREADS} must be an integer >= 1, got {raw!r}")
    return n


def hj_cache_dir() -> Path:
    """``$RMM_HJ_CACHE`` if set and not empty, else ``~/.cache/rmm-envs/hj``."""
    return Path(os.environ.get(HJ_CACHE) or Path.home() / ".cache" / "rmm-envs" / "hj")


def reference_dir() -> Path | None:
    """``$RMM_REFERENCE_DIR`` as a path, or ``None`` when unset or empty (the shipped results)."""
    raw = os.environ.get(REFERENCE_DIR)
    return Path(raw) if raw else None


_SAFE_START = "RMM_POOL_SAFE_START"  # set with PYTHONSAFEPATH by safe_path_start, not by the user


@contextlib.contextmanager
def safe_path_start() -> Iterator[None]:
    """Within: processes started get ``PYTHONSAFEPATH=1`` (Python 3.11+; ignored before), so a
    spawned worker (``python -c ...``) does not put the current directory first on ``sys.path``
    while it starts: a ``multiprocessing.py`` there would be imported in place of Python's own.
    Left as it is when the user set it."""
    if "PYTHONSAFEPATH" in os.environ:
        yield
        return
    os.environ.update({"PYTHONSAFEPATH": "1", _SAFE_START: "1"})
    try:
        yield
    finally:
        for name in ("PYTHONSAFEPATH", _SAFE_START):
            os.environ.pop(name, None)


def safe_path_started() -> None:
    """In a process started within :func:`safe_path_start`: unset what it set, so what this
    process starts in turn behaves as usual."""
    if os.environ.pop(_SAFE_START, None):
        os.environ.pop("PYTHONSAFEPATH", None)
