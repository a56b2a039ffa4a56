"""Rectilinear grids with optional periodic axes, and fast multilinear interpolation.

A non-periodic axis has ``n`` points from ``lo`` to ``hi`` inclusive.  A periodic axis has
``n`` points ``lo + i (hi - lo) / n``: the period is exactly ``hi - lo`` and ``hi`` itself is
the same point as ``lo`` (the original padded its heading axis by 0.1 rad on each side, giving
a period of 2 pi + 0.2).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

njit: Callable[..., Any] | None  # numba's, or None where numba is missing
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; interpolation falls back to numpy
    njit = None

__all__ = ["Grid", "central_gradient"]


class Grid:
    def __init__(self, lo, hi, n, periodic=()) -> None:
        self.lo = np.asarray(lo, dtype=float)
        self.hi = np.asarray(hi, dtype=float)
        self.n = tuple(int(k) for k in n)
        self.ndim = len(self.n)
        if self.lo.shape != (self.ndim,) or self.hi.shape != (self.ndim,):
            raise ValueError(f"lo and hi must have {self.ndim} entries, got {self.lo.shape}, {self.hi.shape}")
        if np.any(self.hi <= self.lo) or min(self.n) < 3:
            raise ValueError(
                f"each axis needs hi > lo and at least 3 points, got lo={self.lo}, hi={self.hi}, n={self.n}"
            )
        self.periodic = tuple(bool(i in set(periodic)) for i in range(self.ndim))
        self.dx = np.array(
            [
                (hi - lo) / (k if p else k - 1)
                for lo, hi, k, p in zip(self.lo, self.hi, self.n, self.periodic, strict=True)
            ]
        )
        self.axes = [lo + d * np.arange(k) for lo, d, k in zip(self.lo, self.dx, self.n, strict=True)]
        self.shape = self.n
        # for interpolation: the 2^d cell corners and the flat-index strides, computed once
        self._corners = np.array(np.meshgrid(*[[0, 1]] * self.ndim, indexing="ij")).reshape(self.ndim, -1).astype(bool)
        self._strides = np.array([int(np.prod(self.n[a + 1 :])) for a in range(self.ndim)], dtype=np.int64)

    def coord(self, axis: int) -> np.ndarray:
        """Axis coordinates shaped to broadcast against the grid."""
        shape = [1] * self.ndim
        shape[axis] = self.n[axis]
        return self.axes[axis].reshape(shape)

    def key(self) -> dict:
        return {"lo": self.lo.tolist(), "hi": self.hi.tolist(), "n": list(self.n), "periodic": list(self.periodic)}

    def contains(self, x) -> bool:
        """Whether a point lies inside the grid's box (periodic axes always do)."""
        x = np.asarray(x, dtype=float)
        return all(p or (lo <= xi <= hi) for xi, lo, hi, p in zip(x, self.lo, self.hi, self.periodic, strict=True))

    def _cell(self, x):
        """Lower corner indices, fractions and upper indices of the cell holding ``x``."""
        x = np.asarray(x, dtype=float)
        t = (x - self.lo) / self.dx
        i0 = np.floor(t)
        frac = t - i0
        i0 = i0.astype(int)
        i1 = i0 + 1
        for a, (k, p) in enumerate(zip(self.n, self.periodic, strict=True)):
            if p:
                i0[a] %= k
                i1[a] %= k
            else:
                if i0[a] >= k - 1:  # exactly on the upper edge
                    i0[a], frac[a] = k - 2, 1.0
                i0[a] = min(max(i0[a], 0), k - 2)
                i1[a] = i0[a] + 1
                frac[a] = min(max(frac[a], 0.0), 1.0)
        return i0, i1, frac

    def interp_many(self, arrays, x) -> np.ndarray:
        """Multilinear interpolation of several same-shape arrays at one point ``x``."""
        i0, i1, frac = self._cell(x)
        c = self._corners
        flat = (np.where(c, i1[:, None], i0[:, None]).T * self._strides).sum(axis=1)  # (2^d,) flat indices
        w = np.prod(np.where(c, frac[:, None], 1.0 - frac[:, None]), axis=0)
        return np.array([np.add.reduce(a.reshape(-1)[flat] * w) for a in arrays])  # ordered sums, not BLAS

    def interpolator(self, arrays):
        """A function ``f(x) -> (len(arrays),)`` interpolating ``arrays`` at one point, as
        :meth:`interp_many` does: the guardians' per-decision lookup.

        With numba it is one compiled call over arrays flattened once here (numpy's per-call
        overhead on the 16 corners of a 4-D cell was most of a decision's time); the corner
        order and weights are :meth:`interp_many`'s, the sums may differ in the last bits
        (sequential rather than numpy's pairwise order; each is the same on every CPU)."""
        arrays = [np.asarray(a) for a in arrays]
        for a in arrays:
            if a.shape != self.shape:
                raise ValueError(f"arrays to interpolate must have the grid's shape {self.shape}, got {a.shape}")
        if njit is None or len({a.dtype for a in arrays}) != 1:  # pragma: no cover - numba is a dependency
            return lambda x: self.interp_many(arrays, x)
        flat = tuple(np.ascontiguousarray(a).reshape(-1) for a in arrays)
        lo, dx = self.lo.copy(), self.dx.copy()
        n = np.array(self.n, dtype=np.int64)
        periodic = np.array(self.periodic, dtype=np.bool_)
        strides = self._strides.copy()

        def interpolate(x):
            return _interp_point(flat, np.asarray(x, dtype=float), lo, dx, n, periodic, strides)

        return interpolate

    def interp(self, array, x) -> float:
        return float(self.interp_many([array], x)[0])


def central_gradient(V: np.ndarray, grid: Grid) -> list[np.ndarray]:
    """``V``'s gradient on ``grid``, one array per axis: central differences in float32 (one-sided
    at non-periodic edges, as ``np.gradient``; periodic axes wrap)."""
    out = []
    for ax in range(grid.ndim):
        n = V.shape[ax]

        def sl(a, b, ax=ax):
            s = [slice(None)] * V.ndim
            s[ax] = slice(a, b)
            return tuple(s)

        g = np.empty_like(V, dtype=np.float32)
        inv2 = np.float32(0.5 / grid.dx[ax])
        np.subtract(V[sl(2, n)], V[sl(0, n - 2)], out=g[sl(1, n - 1)])
        if grid.periodic[ax]:
            np.subtract(V[sl(1, 2)], V[sl(n - 1, n)], out=g[sl(0, 1)])
            np.subtract(V[sl(0, 1)], V[sl(n - 2, n - 1)], out=g[sl(n - 1, n)])
            g *= inv2
        else:
            g[sl(1, n - 1)] *= inv2
            inv = np.float32(1.0 / grid.dx[ax])
            np.multiply(V[sl(1, 2)] - V[sl(0, 1)], inv, out=g[sl(0, 1)])
            np.multiply(V[sl(n - 1, n)] - V[sl(n - 2, n - 1)], inv, out=g[sl(n - 1, n)])
        out.append(g)
    return out


def _interp_point(flat, x, lo, dx, n, periodic, strides):
    """:meth:`Grid.interp_many` at one point over flattened arrays (the compiled path)."""
    d = lo.shape[0]
    i0 = np.empty(d, np.int64)
    i1 = np.empty(d, np.int64)
    frac = np.empty(d)
    for a in range(d):
        t = (x[a] - lo[a]) / dx[a]
        f = math.floor(t)
        frac[a] = t - f
        k = n[a]
        lower = int(f)
        if periodic[a]:
            i0[a] = lower % k
            i1[a] = (lower + 1) % k
        else:
            if lower >= k - 1:  # exactly on the upper edge
                lower, frac[a] = k - 2, 1.0
            lower = min(max(lower, 0), k - 2)
            i0[a] = lower
            i1[a] = lower + 1
            frac[a] = min(max(frac[a], 0.0), 1.0)
    out = np.zeros(len(flat))
    for c in range(1 << d):
        w = 1.0
        idx = 0
        for a in range(d):
            if (c >> (d - 1 - a)) & 1:
                w *= frac[a]
                idx += i1[a] * strides[a]
            else:
                w *= 1.0 - frac[a]
                idx += i0[a] * strides[a]
        for m in range(len(flat)):
            out[m] += flat[m][idx] * w
    return out


if njit is not None:
    _interp_point = njit(cache=True)(_interp_point)
