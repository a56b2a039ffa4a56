"""Rays among circular obstacles: the distance along each of ``n_rays`` directions around a
heading to the first circle, capped at ``max_range`` (:func:`ray_cast`, per origin's own circles
:func:`ray_cast_each`, the numpy reference :func:`ray_cast_numpy`).  Importable from
:mod:`rmm_envs.systems.dubins4d.circles`, whose worlds they observe.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; numpy alone still works
    njit = None

_COMPILED_MAX_N = 8  # ray origins per call up to which the compiled loop beats numpy's overhead

__all__ = ["ray_cast", "ray_cast_each", "ray_cast_numpy"]


def ray_cast(
    origins: np.ndarray,
    headings: np.ndarray,
    circles: np.ndarray,
    n_rays: int = 12,
    max_range: float = 10.0,
) -> np.ndarray:
    """Distances along ``n_rays`` rays to the nearest circle, ``(N, n_rays)``, capped at ``max_range``.

    Ray ``i`` points at ``heading + 2 pi i / n_rays`` (counter-clockwise from straight ahead).
    A ray whose origin lies inside a circle reads 0.  A few origins (an environment step) go
    through a compiled loop of the same formulas, many (a dataset) through numpy.
    """
    origins = np.asarray(origins, dtype=float)[:, :2]
    headings = np.asarray(headings, dtype=float)
    n = origins.shape[0]
    if circles.shape[0] == 0:
        return np.full((n, n_rays), float(max_range))
    if n <= _COMPILED_MAX_N and _ray_cast_compiled is not None:
        return _ray_cast_compiled(
            np.ascontiguousarray(origins),
            np.ascontiguousarray(headings.reshape(n)),
            np.ascontiguousarray(circles, dtype=float),
            int(n_rays),
            float(max_range),
            np.empty((n, int(n_rays))),
        )
    return ray_cast_numpy(origins, headings, circles, n_rays, max_range)


def ray_cast_numpy(origins, headings, circles, n_rays, max_range):
    """:func:`ray_cast`'s numpy path (the one many origins take), whatever their number."""
    ang = headings[:, None] + (2.0 * np.pi / n_rays) * np.arange(n_rays)[None, :]
    dx, dy = np.cos(ang), np.sin(ang)  # (N, R)
    fx = circles[None, :, 0] - origins[:, 0:1]  # (N, K)
    fy = circles[None, :, 1] - origins[:, 1:2]
    cc = fx * fx + fy * fy - circles[None, :, 2] ** 2  # (N, K); <= 0 inside
    b = dx[:, :, None] * fx[:, None, :] + dy[:, :, None] * fy[:, None, :]  # (N, R, K)
    disc = b * b - cc[:, None, :]
    t = b - np.sqrt(np.maximum(disc, 0.0))
    valid = (disc >= 0) & (t >= 0)
    t = np.where(cc[:, None, :] <= 0, 0.0, np.where(valid, t, np.inf))
    return np.minimum(t.min(axis=2), max_range)


def _rays_1(ox, oy, heading, circles, max_range, out, dirs):
    """The ray lengths from one origin into ``out`` (the formulas of the numpy path); ``dirs``:
    ``(n_rays, 2)`` scratch for the rays' directions.  A circle farther than ``max_range``
    from the origin cannot shorten a ray and is skipped (a relative margin of 1e-9 keeps
    rounding from ever mattering); the minimum over the others is order-free."""
    n_rays = out.shape[0]
    step = 2.0 * math.pi / n_rays
    for r in range(n_rays):
        ang = heading + step * r
        dirs[r, 0], dirs[r, 1] = math.cos(ang), math.sin(ang)
        out[r] = max_range
    for k in range(circles.shape[0]):
        fx, fy = circles[k, 0] - ox, circles[k, 1] - oy
        cc = fx * fx + fy * fy - circles[k, 2] ** 2
        if cc <= 0:  # inside: every ray reads 0
            for r in range(n_rays):
                out[r] = 0.0
            return
        reach = max_range + circles[k, 2]
        if fx * fx + fy * fy > reach * reach * (1.0 + 1e-9):
            continue
        for r in range(n_rays):
            b = dirs[r, 0] * fx + dirs[r, 1] * fy
            disc = b * b - cc
            t = b - math.sqrt(max(disc, 0.0))
            if disc >= 0 and t >= 0 and t < out[r]:
                out[r] = t


def _ray_cast_loop(origins, headings, circles, n_rays, max_range, out):
    dirs = np.empty((n_rays, 2))
    for n in range(origins.shape[0]):
        _rays_1(origins[n, 0], origins[n, 1], headings[n], circles, max_range, out[n], dirs)
    return out


def _ray_cast_each_loop(origins, headings, circles, n_rays, max_range, out):
    dirs = np.empty((n_rays, 2))
    for n in range(origins.shape[0]):
        _rays_1(origins[n, 0], origins[n, 1], headings[n], circles[n], max_range, out[n], dirs)
    return out


if njit is not None:  # one source: the compiled loops run the same per-origin function
    _rays_1 = njit(cache=True)(_rays_1)
    _ray_cast_compiled = njit(cache=True)(_ray_cast_loop)
    _ray_cast_each_loop = njit(cache=True)(_ray_cast_each_loop)
else:  # pragma: no cover
    _ray_cast_compiled = None


def ray_cast_each(
    origins: np.ndarray, headings: np.ndarray, circles: np.ndarray, n_rays: int = 12, max_range: float = 10.0
) -> np.ndarray:
    """:func:`ray_cast` for ``N`` origins each among its own circles ``(N, K, 3)``: ``(N, n_rays)``.

    Always the compiled loop (the same per-origin function as :func:`ray_cast`'s for a few
    origins), so an origin's rays do not depend on the batch, bit for bit.
    """
    origins = np.ascontiguousarray(np.asarray(origins, dtype=float)[:, :2])
    headings = np.ascontiguousarray(headings, dtype=float).reshape(origins.shape[0])
    circles = np.ascontiguousarray(circles, dtype=float)
    if circles.ndim != 3 or circles.shape[::2] != (origins.shape[0], 3):
        raise ValueError(f"circles must be (N, K, 3) for {origins.shape[0]} origins, got {circles.shape}")
    out = np.empty((origins.shape[0], int(n_rays)))
    if circles.shape[1] == 0:
        out[:] = float(max_range)
        return out
    return _ray_cast_each_loop(origins, headings, circles, int(n_rays), float(max_range), out)
