"""Arithmetic whose bits do not depend on the machine it runs on.

Three things make a float result depend on the CPU rather than on the inputs alone:

* **BLAS.**  numpy hands ``@``, ``np.dot``, ``np.inner`` and the no-axis ``np.linalg.norm`` to
  OpenBLAS, which picks a kernel per CPU at start-up (``OPENBLAS_CORETYPE``); kernels sum in
  different orders and some use fused multiply-adds.
* **numpy's SIMD dispatch.**  On AVX-512 CPUs numpy computes ``exp``, ``log``, ``arctan2``,
  ``arctan``, ``power``, ... with its own vector code, on AVX2 CPUs ``tanh`` too; each differs
  from the C library in the last bit for some inputs.  (``sin``, ``cos``, ``sqrt``, ``hypot``,
  ``+ - * /`` and numpy's ordered sums ``np.add.reduce`` / ``.sum`` are the same everywhere.)
* **Compiled kernels** built for the host CPU could contract ``a * b + c`` into one FMA; numba
  does not without ``fastmath``, which the project never uses.

So code whose result a seed determines (worlds, dynamics, observations, labels, decisions)
uses the helpers here instead: sums of small products written out in a fixed order, numpy's
ordered reductions, and element-wise ``atan2`` / ``exp`` / ``tanh`` from the C library through a
compiled loop.  ``tests/test_reproducibility.py`` recomputes a fingerprint of everything under
several machines' arithmetic.  What remains machine-dependent is said in docs/reproduction.md.
"""

from __future__ import annotations

import math

import numpy as np
from numba import vectorize

__all__ = ["arctan2", "dot", "matvec", "norm", "norms", "wrap_angle"]


def dot(a, b) -> float:
    """``sum(a[i] * b[i])`` of two short vectors, left to right, as a Python float."""
    s = 0.0
    for x, y in zip(np.asarray(a, float).tolist(), np.asarray(b, float).tolist()):
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
    return np.sqrt(np.add.reduce(a * a, axis=axis, keepdims=keepdims))


def matvec(A, x) -> np.ndarray:
    """``A @ x`` for a small matrix (or a stack of them, ``(..., m, n)``) and ``x (..., n)``,
    as numpy's ordered sum of products instead of a BLAS call."""
    A, x = np.asarray(A, dtype=float), np.asarray(x, dtype=float)
    return np.add.reduce(A * x[..., None, :], axis=-1)


@vectorize(["float64(float64, float64)"], cache=True)
def arctan2(y, x):  # pragma: no cover - compiled
    """Element-wise ``atan2(y, x)`` from the C library (numpy's own is SIMD code on AVX-512)."""
    return math.atan2(y, x)


def wrap_angle(theta):
    """Wrap angles to ``[-pi, pi)`` (exact: ``%`` is a remainder, no transcendental function)."""
    return (np.asarray(theta, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
