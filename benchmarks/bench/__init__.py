"""rmm-bench: run guardians over seeded episodes, store results, report Table I.

``load_results(path)`` reads an ``rmm-bench`` results database into a pandas DataFrame (one
row per stored episode); see :func:`rmm_bench.dataframes.load_results`.  ``table_i(df)``
aggregates such a frame into the paper's Table I, one row per agent.
"""

__all__ = ["load_results", "table_i"]


def load_results(path, *, expand_stats: bool = False):
    """One row per stored episode of the results database at ``path`` (pandas DataFrame)."""
    from rmm_bench.dataframes import load_results as _load  # pandas only when asked for

    return _load(path, expand_stats=expand_stats)


def table_i(df, batch_size: int = 64):
    """Table I (one row per agent) of a DataFrame of episodes; see :func:`rmm_bench.metrics.table_i`."""
    from rmm_bench.metrics import table_i as _table

    return _table(df, batch_size)
