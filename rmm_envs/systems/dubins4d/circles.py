"""Circular obstacles in the plane: generation, exact collision tests and ray casting.

Circles are arrays of shape ``(K, 3)`` holding ``(x_c, y_c, r)``.  Every test here is analytic
and batched: points are ``(N, 2)``, segments are pairs of ``(N, 2)`` arrays, paths are
``(N, S, 2+)``.  Conventions (shared by the environment and the risk estimator): a point or a
segment collides when it comes within ``r`` of a centre (the boundary counts); a path's
*contact parameter* is ``j + s`` for the first segment ``j`` that touches a circle at fraction
``s`` in ``[0, 1]`` along it, ``inf`` when it never touches.  Generation follows the paper's
environment: the first obstacle's centre drawn from ``N(0, 2^2)`` per axis, the others uniform
on the arena square, radii uniform in ``[r_min, r_max]``; obstacles may overlap.

Where this differs from the original (exact circles where it used 64-gons, contacts ordered within
a step): docs/original-code.md, items 2, 3 and 21; why: docs/decisions/0021-exact-models.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rmm_envs.systems.dubins4d.rays import ray_cast, ray_cast_each, ray_cast_numpy
from rmm_envs.worlds.bounds import MAX_MAGNITUDE, within_bounds

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; numpy alone still works
    njit = None

__all__ = [
    "CircleWorld",
    "as_circles",
    "contact_params",
    "contact_params_each",
    "first_contact",
    "points_in_circles",
    "ray_cast",
    "ray_cast_each",
    "ray_cast_numpy",
    "segments_hit_circles",
]


def as_circles(circles, name: str = "circles") -> np.ndarray:
    """Validate and return circles as a float ``(K, 3)`` array with positive radii, every number
    of magnitude at most :data:`rmm_envs.worlds.bounds.MAX_MAGNITUDE`."""
    try:
        arr = np.asarray(circles, dtype=float)
    except OverflowError:  # an integer beyond a float (10**400)
        raise ValueError(
            f"{name} must be numbers of magnitude at most {MAX_MAGNITUDE:g}, got {str(circles)[:200]}"
        ) from None
    if arr.size == 0:
        return np.zeros((0, 3))
    if arr.ndim == 1 and arr.shape[0] == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must be a list of [x, y, r] triples, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {arr.tolist()}")
    if not within_bounds(arr):
        raise ValueError(
            f"{name} must be numbers of magnitude at most {MAX_MAGNITUDE:g} (larger ones overflow the "
            f"geometry), got {arr.tolist()}"
        )
    if np.any(arr[:, 2] <= 0):
        raise ValueError(f"{name} radii must be > 0, got {arr[:, 2].tolist()}")
    return arr


def points_in_circles(points: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: point ``i`` lies in (or on) any circle."""
    points = np.asarray(points, dtype=float)
    if circles.shape[0] == 0:
        return np.zeros(points.shape[0], dtype=bool)
    if points.shape[0] == 1:  # one point (a start being drawn): the same arithmetic without numpy's overhead
        x, y = float(points[0, 0]), float(points[0, 1])
        for cx, cy, r in circles.tolist():
            dx, dy = x - cx, y - cy
            if dx * dx + dy * dy <= r * r:
                return np.ones(1, dtype=bool)
        return np.zeros(1, dtype=bool)
    d = points[:, None, :2] - circles[None, :, :2]
    return np.any(np.einsum("nkj,nkj->nk", d, d) <= circles[None, :, 2] ** 2, axis=1)


def _segment_circle_sq_dist(p0: np.ndarray, p1: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Squared distance from each circle centre to each segment, ``(..., K)``."""
    d = (p1 - p0)[..., None, :]  # (..., 1, 2)
    f = circles[:, :2] - p0[..., None, :]  # (..., K, 2)
    dd = np.sum(d * d, axis=-1)
    fd = np.sum(f * d, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(dd > 0, np.clip(fd / dd, 0.0, 1.0), 0.0)
    g = f - s[..., None] * d
    return np.sum(g * g, axis=-1)


def segments_hit_circles(p0: np.ndarray, p1: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """``(...)`` bool: the closed segment ``p0 -> p1`` touches any circle (exact)."""
    p0 = np.asarray(p0, dtype=float)[..., :2]
    p1 = np.asarray(p1, dtype=float)[..., :2]
    if circles.shape[0] == 0:
        return np.zeros(p0.shape[:-1], dtype=bool)
    return np.any(_segment_circle_sq_dist(p0, p1, circles) <= circles[:, 2] ** 2, axis=-1)


def paths_hit_circles(paths: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: any point or segment of path ``i`` (``(N, S, 2+)``) touches a circle.

    Exact.  Path/circle pairs that cannot touch are skipped first: every point of a polyline
    of length ``L`` lies within ``L / 2`` of the midpoint of its chord (triangle inequality),
    so only circles within ``r + L / 2`` of that midpoint are tested segment by segment.
    """
    paths = np.asarray(paths, dtype=float)
    n = paths.shape[0]
    out = np.zeros(n, dtype=bool)
    if circles.shape[0] == 0 or n == 0:
        return out
    xy = paths[:, :, :2]
    if xy.shape[1] == 1:
        return points_in_circles(xy[:, 0], circles)
    seg = np.diff(xy, axis=1)
    half_len = 0.5 * np.sqrt(np.einsum("nsj,nsj->ns", seg, seg)).sum(axis=1)  # (N,)
    mid = 0.5 * (xy[:, 0] + xy[:, -1])
    dm = mid[:, None, :] - circles[None, :, :2]
    near = np.einsum("nkj,nkj->nk", dm, dm) <= (circles[None, :, 2] + half_len[:, None]) ** 2
    idx, k = np.nonzero(near)
    if idx.size == 0:
        return out
    a = xy[idx, :-1]  # (P, S-1, 2)
    d = seg[idx]
    c = circles[k]  # (P, 3)
    f = c[:, None, :2] - a
    dd = np.einsum("psj,psj->ps", d, d)
    fd = np.einsum("psj,psj->ps", f, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(dd > 0, np.clip(fd / dd, 0.0, 1.0), 0.0)
    g = f - s[..., None] * d
    hit = np.any(np.einsum("psj,psj->ps", g, g) <= (c[:, 2] ** 2)[:, None], axis=1)
    out[idx[hit]] = True
    return out


def contact_params(path_xy: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Contact parameter ``j + s`` of one path ``(S, 2+)`` with each circle, ``(K,)``.

    Segment ``j`` runs from point ``j`` to point ``j + 1``; ``s`` is the exact fraction along it
    where the path first enters the circle (``0`` when point ``j`` is already inside).
    ``inf`` for a circle the path never touches.  :func:`contact_params_each` with ``N = 1``.
    """
    xy = np.asarray(path_xy, dtype=float)
    circles = np.asarray(circles, dtype=float)
    if circles.shape[0] == 0:
        return np.zeros(0)
    return contact_params_each(xy[None], circles[None])[0]


def contact_params_each(paths: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Contact parameters of ``N`` paths ``(N, S, 2+)``, each with its own circles ``(N, K, 3)``:
    ``(N, K)``, as :func:`contact_params` per path.

    One compiled loop (the same Python function without numba) whatever ``N``: a path's result
    does not depend on the batch it is computed in, bit for bit.  A single-point path
    (``S = 1``) has contact ``0`` with the circles holding its point.
    """
    paths = np.ascontiguousarray(paths, dtype=float)
    circles = np.ascontiguousarray(circles, dtype=float)
    if paths.ndim != 3 or paths.shape[2] < 2 or circles.ndim != 3 or circles.shape[::2] != (paths.shape[0], 3):
        raise ValueError(f"paths must be (N, S, 2+) and circles (N, K, 3), got {paths.shape} and {circles.shape}")
    return _contact_loop(paths, circles, np.empty(circles.shape[:2]))


def _contact_loop(paths, circles, out):
    for n in range(paths.shape[0]):
        # every point, hence every segment, of the path lies within `reach` of its first point:
        # a circle farther than r + reach from it cannot be touched (skip the exact test)
        reach2 = 0.0
        for j in range(1, paths.shape[1]):
            qx, qy = paths[n, j, 0] - paths[n, 0, 0], paths[n, j, 1] - paths[n, 0, 1]
            reach2 = max(reach2, qx * qx + qy * qy)
        reach = math.sqrt(reach2)
        for k in range(circles.shape[1]):
            cx, cy, r = circles[n, k, 0], circles[n, k, 1], circles[n, k, 2]
            best = math.inf
            gx, gy = paths[n, 0, 0] - cx, paths[n, 0, 1] - cy
            if gx * gx + gy * gy > (r + reach) * (r + reach):
                out[n, k] = best
                continue
            if paths.shape[1] == 1:
                fx, fy = paths[n, 0, 0] - cx, paths[n, 0, 1] - cy
                if fx * fx + fy * fy <= r * r:
                    best = 0.0
            for j in range(paths.shape[1] - 1):
                px, py = paths[n, j, 0], paths[n, j, 1]
                dx, dy = paths[n, j + 1, 0] - px, paths[n, j + 1, 1] - py
                fx, fy = px - cx, py - cy
                c = (fx * fx + fy * fy) - r * r  # <= 0: the segment starts inside
                if c <= 0:
                    best = float(j)
                    break
                a = dx * dx + dy * dy
                b = fx * dx + fy * dy  # half the linear coefficient
                disc = b * b - a * c
                if a > 0 and disc >= 0:
                    s_in = (-b - math.sqrt(disc)) / a
                    if 0 <= s_in <= 1:
                        best = j + s_in
                        break
            out[n, k] = best
    return out


_contact_loop = njit(cache=True)(_contact_loop) if njit is not None else _contact_loop


def first_contact(path_xy: np.ndarray, circles: np.ndarray) -> float:
    """Contact parameter of one path with the union of ``circles`` (``inf`` if none)."""
    cp = contact_params(path_xy, circles)
    return float(cp.min()) if cp.size else float("inf")


@dataclass
class CircleWorld:
    """A set of circular obstacles and a circular goal region.

    Args:
        obstacles: ``(K, 3)`` circles ``(x, y, r)``.
        goal: ``(3,)`` goal circle ``(x, y, r)``.
    """

    obstacles: np.ndarray
    goal: np.ndarray = field(default_factory=lambda: np.array([np.inf, np.inf, 1.0]))

    def __post_init__(self) -> None:
        self.obstacles = as_circles(self.obstacles, "obstacles")
        goal = np.asarray(self.goal, dtype=float).reshape(-1)
        if goal.shape != (3,) or not (goal[2] > 0) or np.isnan(goal).any():
            raise ValueError(f"goal must be [x, y, r] with r > 0, got {goal.tolist()}")
        self.goal = goal

    @staticmethod
    def generate(
        rng: np.random.Generator,
        n_obstacles: int = 5,
        r_min: float = 2.0,
        r_max: float = 5.0,
        half_width: float = 10.0,
        centre_std: float = 2.0,
    ) -> np.ndarray:
        """Random obstacles as in the paper: the first near the centre, the rest uniform."""
        obs = np.empty((n_obstacles, 3))
        for i in range(n_obstacles):
            if i == 0:
                obs[i, :2] = rng.normal(0.0, centre_std, size=2)
            else:
                obs[i, :2] = rng.uniform(-half_width, half_width, size=2)
            obs[i, 2] = rng.uniform(r_min, r_max)
        return obs
        # Draw order: centre 0 (normal), radius 0, then (x, y, r) of each other obstacle.  The
        # uniform draws after the first come from one call with per-element bounds, which
        # consumes the generator exactly as one call per number would (same numbers, faster).
        obs[0, :2] = rng.normal(0.0, centre_std, size=2)
        obs[0, 2] = rng.uniform(r_min, r_max)
        if n_obstacles > 1:
            k = n_obstacles - 1
            obs[1:] = rng.uniform(
                np.array([-half_width, -half_width, r_min] * k), np.array([half_width, half_width, r_max] * k)
            ).reshape(k, 3)
        return obs

    def in_collision(self, points: np.ndarray) -> np.ndarray:
        return points_in_circles(points, self.obstacles)

    def in_goal(self, points: np.ndarray) -> np.ndarray:
        return points_in_circles(points, self.goal[None, :])

    def rays(self, states: np.ndarray, n_rays: int = 12, max_range: float = 10.0) -> np.ndarray:
        states = np.asarray(states, dtype=float)
        return ray_cast(states[:, :2], states[:, 2], self.obstacles, n_rays, max_range)
