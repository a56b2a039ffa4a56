"""Results as a table: :func:`load_results` reads a results database into a pandas DataFrame."""

from __future__ import annotations

import json
from pathlib import Path

from rmm_bench.store import ResultsStore

__all__ = ["load_results"]


def load_results(path, *, expand_stats: bool = False):
    """Every stored episode of a ``rmm-bench`` results database, one row each.

    ``path`` is a results directory (holding ``results.db``) or the database file itself.
    The columns are the stored fields (``agent``, ``seed``, ``episode``, ``outcome``, ``steps``,
    ``sim_time``, ``active_sim_time``, ``final_speed``, ``error``, ... exactly as stored) plus
    the run's ``config`` (a dict: environment, clock, guardian options).  Rows are ordered by
    agent, then episode.  ``expand_stats=True`` adds one ``stats.<name>`` column per key of the
    guardians' ``stats()`` (for example ``stats.recoveries`` of ``cbf``), NaN where a guardian
    did not report it.  Reading never changes the database; a damaged file raises
    :class:`~rmm_bench.store.ResultsDatabaseError` naming it.
    """
    import pandas as pd

    p = Path(path)
    db = p / "results.db" if p.is_dir() else p
    if not db.is_file():
        raise FileNotFoundError(
            f"no results database at {db} (expected a directory written by rmm-bench, or its results.db)"
        )
    store = ResultsStore(db, read_only=True)
    try:
        df = pd.read_sql_query(
            "SELECT e.*, r.config AS config FROM episodes e JOIN runs r ON r.run_key = e.run_key "
            "ORDER BY e.agent, e.episode, e.run_key",
            store.db,
        )
    finally:
        store.close()
    df["config"] = [json.loads(c) for c in df["config"]]
    if expand_stats:
        stats = pd.DataFrame([json.loads(s) if s else {} for s in df["guardian_stats"]], index=df.index)
        df = pd.concat([df, stats.add_prefix("stats.")], axis=1)
    return df
