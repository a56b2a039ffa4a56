"""Benchmark harness (rmm-bench) and performance measurements.

``load_results(path)`` reads an ``rmm-bench`` results database into a pandas DataFrame (one
row per stored episode); see :func:`benchmarks.bench.frames.load_results`.
"""

__all__ = ["load_results"]


def load_results(path, *, expand_stats: bool = False):
    """One row per stored episode of the results database at ``path`` (pandas DataFrame)."""
    from benchmarks.bench.frames import load_results as _load  # pandas only when asked for

    return _load(path, expand_stats=expand_stats)
