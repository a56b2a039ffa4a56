"""rmm-bench: run guardians over seeded episodes, store results, report Table I.

``load_results(path)`` reads an ``rmm-bench`` results database into a pandas DataFrame (one
row per stored episode); see :func:`rmm_bench.dataframes.load_results`.  ``table_i(df)``
aggregates such a frame into the paper's Table I, one row per agent
(:func:`rmm_bench.metrics.table_i`).  Both import pandas only when called.
"""

from rmm_bench.dataframes import load_results
from rmm_bench.metrics import table_i

__all__ = ["load_results", "table_i"]
