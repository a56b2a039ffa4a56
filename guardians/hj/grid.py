"""Rectilinear grids with optional periodic axes, and fast multilinear interpolation.

A non-periodic axis has ``n`` points from ``lo`` to ``hi`` inclusive.  A periodic axis has
``n`` points ``lo + i (hi - lo) / n``: the period is exactly ``hi - lo`` and ``hi`` itself is
the same point as ``lo`` (the original padded its heading axis by 0.1 rad on each side, giving
a period of 2 pi + 0.2).
"""

from __future__ import annotations

import numpy as np

__all__ = ["Grid"]


class Grid:
    def __init__(self, lo, hi, n, periodic=()) -> None:
        self.lo = np.asarray(lo, dtype=float)
        self.hi = np.asarray(hi, dtype=float)
        self.n = tuple(int(k) for k in n)
        self.ndim = len(self.n)
        if self.lo.shape != (self.ndim,) or self.hi.shape != (self.ndim,):
            raise ValueError(f"lo and hi must have {self.ndim} entries, got {self.lo.shape}, {self.hi.shape}")
        if np.any(self.hi <= self.lo) or min(self.n) < 3:
            raise ValueError(f"each axis needs hi > lo and at least 3 points, got lo={self.lo}, hi={self.hi}, n={self.n}")
        self.periodic = tuple(bool(i in set(periodic)) for i in range(self.ndim))
        self.dx = np.array([(h - l) / (k if p else k - 1) for l, h, k, p in zip(self.lo, self.hi, self.n, self.periodic)])
        self.axes = [l + d * np.arange(k) for l, d, k in zip(self.lo, self.dx, self.n)]
        self.shape = self.n
        # for interpolation: the 2^d cell corners and the flat-index strides, computed once
        self._corners = np.array(np.meshgrid(*[[0, 1]] * self.ndim, indexing="ij")).reshape(self.ndim, -1).astype(bool)
        self._strides = np.array([int(np.prod(self.n[a + 1:])) for a in range(self.ndim)], dtype=np.int64)

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
        return all(p or (l <= xi <= h) for xi, l, h, p in zip(x, self.lo, self.hi, self.periodic))

    def _cell(self, x):
        """Lower corner indices, fractions and upper indices of the cell holding ``x``."""
        x = np.asarray(x, dtype=float)
        t = (x - self.lo) / self.dx
        i0 = np.floor(t)
        frac = t - i0
        i0 = i0.astype(int)
        i1 = i0 + 1
        for a, (k, p) in enumerate(zip(self.n, self.periodic)):
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
        flat = np.where(c, i1[:, None], i0[:, None]).T @ self._strides  # (2^d,)
        w = np.prod(np.where(c, frac[:, None], 1.0 - frac[:, None]), axis=0)
        return np.array([a.reshape(-1)[flat] @ w for a in arrays])

    def interp(self, array, x) -> float:
        return float(self.interp_many([array], x)[0])
