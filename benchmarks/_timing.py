"""Small timing helpers: medians over repeats (machines here are shared and noisy)."""

from __future__ import annotations

import statistics
import time


def median_time(fn, repeats: int = 7, number: int = 1) -> float:
    """Median over ``repeats`` of the mean time of ``number`` calls of ``fn()``, seconds."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return statistics.median(times)


def fmt_us(s: float) -> str:
    return f"{s * 1e6:9.2f} us"
