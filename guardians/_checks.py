"""Argument checks shared by the guardians' constructors: a bad value is refused with a
message that names the argument, the value and what was expected."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["finite", "integer", "number_pair"]


def finite(name: str, value, lo: float | None = None, lo_open: bool = False) -> float:
    """``value`` as a float, refused (naming it) unless finite and, if ``lo`` is given, at least
    ``lo`` (above it with ``lo_open``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or (lo is not None and (x <= lo if lo_open else x < lo)):
        bound = "" if lo is None else f" {'>' if lo_open else '>='} {lo}"
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    return x


def integer(name: str, value, lo: int, what: str = "") -> int:
    """``value`` as an int, refused (naming it) unless an integer (not a bool) ``>= lo``;
    ``what`` explains the argument in the message."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}{f' ({what})' if what else ''}, got {value!r}")
    return int(value)


def number_pair(name: str, pair) -> tuple[float, float]:
    """``(min, max)`` as floats, refused (naming it) unless both finite with ``min < max``."""
    try:
        lo, hi = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (min, max) pair of numbers, got {pair!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise ValueError(f"{name} must be a finite (min, max) with min < max, got {pair!r}")
    return lo, hi


# the systems' checks live in guardians.dispatch; guardians.hj.quadrotor imports quadrotor_only from here
from guardians.dispatch import quadrotor_only  # noqa: E402
