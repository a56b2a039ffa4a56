"""The statistics of a paired comparison of two agents: intervals for the difference of two
proportions (paired and unpaired, Newcombe), the exact McNemar test, and a paired bootstrap.

Offers :func:`newcombe_paired`, :func:`newcombe_unpaired`, :func:`mcnemar_exact`,
:func:`paired_bootstrap` and :data:`Z95`; :mod:`rmm_bench.compare` applies them to stored runs.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_bench.metrics import wilson_interval

__all__ = ["Z95", "concordance", "mcnemar_exact", "newcombe_paired", "newcombe_unpaired", "paired_bootstrap"]

#: z of a two-sided 95% interval
Z95 = 1.959963984540054


def concordance(fa, fb) -> tuple[int, int, int, int]:
    """``(both, a_only, b_only, neither)``: how many paired episodes have the outcome in both, in
    ``a`` only, in ``b`` only and in neither (``fa``, ``fb``: the outcome's flags, episode by episode)."""
    fa, fb = np.asarray(fa, bool), np.asarray(fb, bool)
    return int((fa & fb).sum()), int((fa & ~fb).sum()), int((~fa & fb).sum()), int((~fa & ~fb).sum())


def newcombe_paired(both: int, a_only: int, b_only: int, neither: int, z: float = Z95) -> tuple[float, float, float]:
    """The difference ``p_a - p_b`` of two proportions measured on the same ``n`` episodes and its
    interval by Newcombe's method 10 for paired data (Statistics in Medicine 17, 1998, 2635-2650):
    Wilson score intervals ``(l, u)`` of both margins, combined as
    ``D - sqrt((p_a - l_a)^2 - 2 phi (p_a - l_a)(u_b - p_b) + (u_b - p_b)^2)`` below and the mirror
    above, where ``phi`` is the correlation of the two outcomes over the episodes: ``(both * neither
    - a_only * b_only)`` less ``n / 2`` when it exceeds ``n / 2``, 0 between 0 and ``n / 2``, kept
    when negative, over the square root of the product of the four margins (0 when one is 0).
    Returns ``(diff, low, high)``."""
    n = both + a_only + b_only + neither
    if n <= 0:
        return math.nan, math.nan, math.nan
    pa, pb = (both + a_only) / n, (both + b_only) / n
    la, ua = wilson_interval(pa, n, z)
    lb, ub = wilson_interval(pb, n, z)
    margins = float(both + a_only) * float(b_only + neither) * float(both + b_only) * float(a_only + neither)
    cross = float(both) * float(neither) - float(a_only) * float(b_only)
    if margins == 0:
        phi = 0.0
    else:
        adjusted = cross - n / 2 if cross > n / 2 else (cross if cross < 0 else 0.0)
        phi = adjusted / math.sqrt(margins)
    d = pa - pb
    low = d - math.sqrt(max(0.0, (pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2))
    high = d + math.sqrt(max(0.0, (ua - pa) ** 2 - 2 * phi * (ua - pa) * (pb - lb) + (pb - lb) ** 2))
    return d, max(-1.0, low), min(1.0, high)


def newcombe_unpaired(x_a: int, n_a: int, x_b: int, n_b: int, z: float = Z95) -> tuple[float, float, float]:
    """The difference of two independent proportions ``x_a / n_a - x_b / n_b`` and Newcombe's
    hybrid score interval (method 10 of Statistics in Medicine 17, 1998, 873-890): Wilson
    intervals of each, combined by squares and a root.  Returns ``(diff, low, high)``."""
    if n_a <= 0 or n_b <= 0:
        return math.nan, math.nan, math.nan
    pa, pb = x_a / n_a, x_b / n_b
    la, ua = wilson_interval(pa, n_a, z)
    lb, ub = wilson_interval(pb, n_b, z)
    d = pa - pb
    return d, max(-1.0, d - math.hypot(pa - la, ub - pb)), min(1.0, d + math.hypot(ua - pa, pb - lb))


def mcnemar_exact(a_only: int, b_only: int) -> float:
    """The exact (binomial) two-sided McNemar p-value of the discordant counts: under the null
    hypothesis that both agents fail equally often, each discordant episode is ``A only`` with
    probability 1/2; 1.0 with no discordant episode."""
    m = a_only + b_only
    if m == 0:
        return 1.0
    from scipy.stats import binomtest

    return float(binomtest(a_only, m, 0.5).pvalue)


def paired_bootstrap(
    x: np.ndarray, y: np.ndarray, seed: int = 0, resamples: int = 2000, level: float = 0.95
) -> tuple[float, float, float]:
    """The mean of ``x - y`` over paired values and its percentile bootstrap interval: the
    episodes resampled with replacement ``resamples`` times by numpy's PCG64 seeded with
    ``seed`` (the same interval for the same inputs and seed).  Returns ``(diff, low, high)``."""
    d = np.asarray(x, float) - np.asarray(y, float)
    if d.size == 0:
        return math.nan, math.nan, math.nan
    rng = np.random.Generator(np.random.PCG64(seed))
    means = np.empty(resamples)
    chunk = max(1, 4_000_000 // d.size)  # at most a few million indices at once
    for start in range(0, resamples, chunk):
        k = min(chunk, resamples - start)
        means[start : start + k] = d[rng.integers(0, d.size, size=(k, d.size))].mean(axis=1)
    tail = (1.0 - level) / 2
    low, high = np.quantile(means, [tail, 1.0 - tail])
    return float(d.mean()), float(low), float(high)
