"""Ghost cells of the padded float32 grids the compiled HJ kernels (:mod:`rmm_guardians.hj._kernels`)
update: one or two per side of each axis, the heading's periodic copies and the other axes' linear
extrapolations, filled by scalar loops over the flattened array (whole-face array expressions took
numba seconds to compile for a 4-D array).  The padding: :class:`rmm_guardians.hj._kernels.Dubins4DStepper`.
"""

from __future__ import annotations

import numpy as np

try:  # numba is a dependency, but the solver keeps a numpy path that works without it
    from numba import njit

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover - exercised only where numba is missing
    HAVE_NUMBA = False

__all__: list[str] = []

if HAVE_NUMBA:

    @njit(cache=True, boundscheck=False)
    def _fill_plane_ghosts2(pl, n2, n3):
        """Two ghosts per side of one flattened (theta, v) plane: heading periodic, speed
        extrapolated linearly (``w[-k] = w[0] + k (w[0] - w[1])``)."""
        for m in range(n3):
            pl[m] = pl[(n2 - 4) * n3 + m]
            pl[n3 + m] = pl[(n2 - 3) * n3 + m]
            pl[(n2 - 2) * n3 + m] = pl[2 * n3 + m]
            pl[(n2 - 1) * n3 + m] = pl[3 * n3 + m]
        two = np.float32(2.0)
        for k in range(n2):
            r = k * n3
            d = pl[r + 2] - pl[r + 3]
            pl[r + 1] = pl[r + 2] + d
            pl[r] = pl[r + 2] + two * d
            e = pl[r + n3 - 3] - pl[r + n3 - 4]
            pl[r + n3 - 2] = pl[r + n3 - 3] + e
            pl[r + n3 - 1] = pl[r + n3 - 3] + two * e

    @njit(cache=True, boundscheck=False)
    def _extrapolate2(Pf, lo, hi, stride, count):
        """Two ghost slabs of ``count`` entries, ``stride`` apart, below the first inner slab at
        ``lo + 2 stride`` and above the last at ``hi - 2 stride``: linear extrapolation."""
        two = np.float32(2.0)
        for k in range(count):
            d = Pf[lo + 2 * stride + k] - Pf[lo + 3 * stride + k]
            Pf[lo + stride + k] = Pf[lo + 2 * stride + k] + d
            Pf[lo + k] = Pf[lo + 2 * stride + k] + two * d
            e = Pf[hi - 2 * stride + k] - Pf[hi - 3 * stride + k]
            Pf[hi - stride + k] = Pf[hi - 2 * stride + k] + e
            Pf[hi + k] = Pf[hi - 2 * stride + k] + two * e

    @njit(cache=True, boundscheck=False)
    def _fill_xy_ghosts2(P):
        """Two ghost faces per side of the position axes (linear extrapolation)."""
        # Scalar loops over the flattened array: the same arithmetic as whole-face array
        # expressions, which numba takes seconds to compile for a 4-D array.
        n0, n1 = P.shape[0], P.shape[1]
        plane = P.shape[2] * P.shape[3]
        sx = n1 * plane
        Pf = P.reshape(-1)
        _extrapolate2(Pf, 0, (n0 - 1) * sx, sx, sx)  # the x faces, whole (y, theta, v) slabs
        for i in range(n0):  # then the y faces of every x row, ghost rows included
            _extrapolate2(Pf, i * sx, i * sx + (n1 - 1) * plane, plane, plane)

    @njit(cache=True, boundscheck=False)
    def _fill_plane_ghosts(pl, n2, n3):
        """Ghosts of one flattened (theta, v) plane: heading periodic, then speed extrapolated."""
        two = np.float32(2.0)
        for m in range(n3):
            pl[m] = pl[(n2 - 2) * n3 + m]
            pl[(n2 - 1) * n3 + m] = pl[n3 + m]
        for k in range(n2):
            pl[k * n3] = two * pl[k * n3 + 1] - pl[k * n3 + 2]
            pl[k * n3 + n3 - 1] = two * pl[k * n3 + n3 - 2] - pl[k * n3 + n3 - 3]

    @njit(cache=True, boundscheck=False)
    def _extrapolate(Pf, lo, hi, stride, count):
        """One ghost slab of ``count`` entries below ``lo + stride`` and one above ``hi - stride``
        (``stride`` apart): linear extrapolation."""
        two = np.float32(2.0)
        for k in range(count):
            Pf[lo + k] = two * Pf[lo + stride + k] - Pf[lo + 2 * stride + k]
            Pf[hi + k] = two * Pf[hi - stride + k] - Pf[hi - 2 * stride + k]

    @njit(cache=True, boundscheck=False)
    def _fill_xy_ghosts(P):
        """Ghost faces of the two position axes (linear extrapolation), whole (theta, v) planes."""
        n0, n1 = P.shape[0], P.shape[1]
        plane = P.shape[2] * P.shape[3]
        sx = n1 * plane
        Pf = P.reshape(-1)
        _extrapolate(Pf, 0, (n0 - 1) * sx, sx, sx)
        for i in range(n0):
            _extrapolate(Pf, i * sx, i * sx + (n1 - 1) * plane, plane, plane)

    @njit(cache=True, boundscheck=False)
    def _fill_ghosts(P, ghosts):
        """All ``ghosts`` (1 or 2) ghost cells per side: every (theta, v) plane's, then the position faces."""
        n0, n1, n2, n3 = P.shape
        plane = n2 * n3
        Pf = P.reshape(-1)
        for i in range(n0):
            for j in range(n1):
                pl = Pf[(i * n1 + j) * plane : (i * n1 + j + 1) * plane]
                if ghosts == 1:
                    _fill_plane_ghosts(pl, n2, n3)
                else:
                    _fill_plane_ghosts2(pl, n2, n3)
        if ghosts == 1:
            _fill_xy_ghosts(P)
        else:
            _fill_xy_ghosts2(P)
