"""Arithmetic whose bits do not depend on the machine it runs on.

BLAS (``@``, ``np.dot``, the no-axis ``np.linalg.norm``) and numpy's SIMD transcendentals pick
code per CPU and differ in the last bit.  So code whose result a seed determines (worlds,
dynamics, observations, labels, decisions) uses the helpers here instead: sums of small
products written out in a fixed order, numpy's ordered reductions, and the C library's
``atan2`` through a compiled loop.  The promise is for x86-64 CPUs with AVX2 and FMA, on Linux
with the same C library; ``tests/test_reproducibility.py`` checks it.

What makes a result machine-dependent, and why these helpers avoid it:
docs/decisions/0005-machine-independent-arithmetic.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["arctan2", "dot", "matvec", "norm", "norms", "wrap_angle"]


def dot(a, b) -> float:
    """``sum(a[i] * b[i])`` of two short vectors of one length, left to right, as a Python float."""
    s = 0.0
    for x, y in zip(np.asarray(a, float).ravel().tolist(), np.asarray(b, float).ravel().tolist(), strict=True):
        s += x * y
    return s


def norm(v) -> float:
    """The Euclidean norm of a short vector: ``sqrt`` of its squares summed left to right."""
    s = 0.0
    for x in np.asarray(v, float).ravel().tolist():
        s += x * x
    return math.sqrt(s)


def norms(a, axis: int = -1, keepdims: bool = False) -> np.ndarray:
    """Euclidean norms along ``axis`` (numpy's ordered sum of squares, never BLAS)."""
    a = np.asarray(a, dtype=float)
    sq = a * a
    return np.sqrt(np.add.reduce(sq, axis=axis, keepdims=True) if keepdims else np.add.reduce(sq, axis=axis))


def matvec(A, x) -> np.ndarray:
    """``A @ x`` for a small matrix (or a stack of them, ``(..., m, n)``) and ``x (..., n)``,
    as numpy's ordered sum of products instead of a BLAS call."""
    A, x = np.asarray(A, dtype=float), np.asarray(x, dtype=float)
    return np.add.reduce(A * x[..., None, :], axis=-1)


@njit(cache=True)
def _atan2_into(y, x, out):  # pragma: no cover - compiled
    for i in range(out.size):
        out[i] = math.atan2(y[i], x[i])


def arctan2(y, x):
    """Element-wise ``atan2(y, x)`` from the C library, broadcast like ``np.arctan2`` (numpy's
    own is SIMD code on AVX-512).  A 0-d result is returned as a numpy float."""
    y, x = np.broadcast_arrays(np.asarray(y, dtype=float), np.asarray(x, dtype=float))
    out = np.empty(y.shape)
    _atan2_into(np.ascontiguousarray(y).ravel(), np.ascontiguousarray(x).ravel(), out.reshape(-1))
    return out[()] if out.ndim == 0 else out


def wrap_angle(theta):
    """Wrap angles to ``[-pi, pi)`` (exact: ``%`` is a remainder, no transcendental function)."""
    return (np.asarray(theta, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
