"""Running independent tasks on local worker processes or on Ray, results as they complete.

Used by ``rmm-datagen`` (one task per shard) and ``rmm-bench`` (one task per episode).  Both
yield ``fn(task)`` results in completion order and clean up on any error or Ctrl-C: local
workers are terminated, pending Ray tasks cancelled, so the caller's own bookkeeping (shards
on disk, rows in SQLite) stays the only record of what finished.
"""

from __future__ import annotations

import os
from typing import Callable, Iterable, Iterator

__all__ = ["run_local", "run_ray"]


def run_local(fn: Callable, tasks: list, workers: int) -> Iterator:
    """``fn(task)`` for each task, in ``workers`` spawned processes (in this process if 1)."""
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if workers == 1 or len(tasks) <= 1:
        for t in tasks:
            yield fn(t)
        return
    import multiprocessing as mp

    pool = mp.get_context("spawn").Pool(min(workers, len(tasks)))
    try:
        yield from pool.imap_unordered(fn, tasks, chunksize=1)
        pool.close()
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()


def run_ray(fn: Callable, tasks: Iterable, address: str | None = None) -> Iterator:
    """``fn(task)`` for each task as Ray tasks (``address`` of a cluster, else a local Ray)."""
    try:
        import ray
    except ImportError as e:
        raise RuntimeError("the Ray backend needs Ray: pip install 'rmm-envs[ray]'") from e
    if not ray.is_initialized():
        if address:
            ray.init(address=address)
        else:
            ray.init(num_cpus=os.cpu_count() or 1, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(fn)
    pending = [remote.remote(t) for t in tasks]
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                yield ray.get(ref)
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
