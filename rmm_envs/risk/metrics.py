"""Coherent risk metrics as reducers over the children of a tree node.

Each reducer maps an array ``(..., n)`` of child values in ``[0, 1]`` to ``(...)``:

* ``expected``: the mean (the paper's choice: with binary failure costs the root value is a
  probability of failure).
* ``cvar`` at level ``alpha`` in ``(0, 1)``: the mean of the worst ``alpha`` fraction of the
  children, exact for the empirical distribution (a child straddling the cut counts
  fractionally).  ``alpha -> 1`` approaches the mean, ``alpha -> 0`` the worst case.
* ``worst``: the maximum.
"""

from __future__ import annotations

import math
from functools import partial

import numpy as np

__all__ = ["METRICS", "cvar", "expected", "get_metric", "worst_case"]


def expected(values: np.ndarray) -> np.ndarray:
    return values.mean(axis=-1)


def worst_case(values: np.ndarray) -> np.ndarray:
    return values.max(axis=-1)


def _cvar_weights(n: int, alpha: float) -> np.ndarray:
    # child i (0 = worst) carries mass min(1/n, max(alpha - i/n, 0)) of the alpha tail
    i = np.arange(n)
    return np.clip(alpha - i / n, 0.0, 1.0 / n) / alpha


def cvar(values: np.ndarray, alpha: float) -> np.ndarray:
    n = values.shape[-1]
    desc = -np.sort(-values, axis=-1)
    return np.add.reduce(
        desc * _cvar_weights(n, alpha), axis=-1
    )  # an ordered sum, not BLAS: the same bits on every CPU


METRICS = ("expected", "cvar", "worst")


def get_metric(name: str, alpha: float | None = None):
    """The reducer called ``name`` (``expected``, ``cvar`` with ``alpha``, ``worst``)."""
    if name == "expected":
        return expected
    if name in ("worst", "worst_case"):
        return worst_case
    if name == "cvar":
        if alpha is None or not (isinstance(alpha, (int, float)) and 0 < alpha < 1 and math.isfinite(alpha)):
            raise ValueError(f"cvar needs alpha in the open interval (0, 1), got {alpha!r}")
        return partial(cvar, alpha=float(alpha))
    raise ValueError(f"unknown risk metric {name!r}; expected one of {list(METRICS)}")
