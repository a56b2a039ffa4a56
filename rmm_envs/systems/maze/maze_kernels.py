"""Compiled maze geometry for one car: the per-step queries of ``Dubins3DMazeGuarded-v0``.

The queries of :class:`rmm_envs.systems.maze.mazes.Maze` for a single car, with the same formulas in
compiled loops (numba, a dependency; plain Python without it), since numpy costs 0.2-0.7 ms a
call for one car (its per-operation overhead over a few hundred walls):

* :func:`maze_rays`: the ray lengths of :meth:`Maze.rays`;
* :func:`maze_path_hit`: :meth:`Maze.paths_hit` for one path, tested against **every** wall
  whose bounding box, grown by the wall's half thickness, meets the path's (numpy's tests the
  walls near the path's first point only, which holds for short paths);
* :func:`dubins_path`: the car's exact path under a held turn rate (the closed forms of
  :meth:`rmm_envs.systems.maze.dynamics.Dubins3D.propagate`, compiled);
* :func:`path_reaches_disc`: whether a path comes within a disc, for the goal.

Tests check them against the numpy versions on random poses and paths.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import segment_position

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; plain Python still works
    njit = None

__all__ = ["dubins_path", "maze_path_hit", "maze_rays", "path_reaches_disc"]


def _seg_point_sq(ax, ay, bx, by, px, py):
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    t = ((px - ax) * dx + (py - ay) * dy) / dd if dd > 0 else 0.0
    t = min(max(t, 0.0), 1.0)
    ex, ey = ax + t * dx - px, ay + t * dy - py
    return ex * ex + ey * ey


def _seg_seg_sq(p0x, p0y, p1x, p1y, q0x, q0y, q1x, q1y):
    d = min(
        min(_seg_point_sq(q0x, q0y, q1x, q1y, p0x, p0y), _seg_point_sq(q0x, q0y, q1x, q1y, p1x, p1y)),
        min(_seg_point_sq(p0x, p0y, p1x, p1y, q0x, q0y), _seg_point_sq(p0x, p0y, p1x, p1y, q1x, q1y)),
    )
    o1 = (p1x - p0x) * (q0y - p0y) - (p1y - p0y) * (q0x - p0x)
    o2 = (p1x - p0x) * (q1y - p0y) - (p1y - p0y) * (q1x - p0x)
    o3 = (q1x - q0x) * (p0y - q0y) - (q1y - q0y) * (p0x - q0x)
    o4 = (q1x - q0x) * (p1y - q0y) - (q1y - q0y) * (p1x - q0x)
    if o1 * o2 < 0 and o3 * o4 < 0:
        return 0.0
    return d


def _clearance(walls, half, px, py):
    best = np.inf
    for k in range(walls.shape[0]):
        best = min(best, _seg_point_sq(walls[k, 0], walls[k, 1], walls[k, 2], walls[k, 3], px, py))
    return math.sqrt(best) - half


def _ray_capsule(ox, oy, dx, dy, ax, ay, bx, by, r):
    ex, ey = bx - ax, by - ay
    L = math.sqrt(ex * ex + ey * ey)
    if L > 0:
        ux, uy = ex / L, ey / L
    else:
        ux, uy = 1.0, 0.0
    nx, ny = -uy, ux
    best = np.inf
    dn = dx * nx + dy * ny
    if dn != 0.0:
        for sgn in (1.0, -1.0):
            cx, cy = ax + sgn * r * nx, ay + sgn * r * ny
            t = ((cx - ox) * nx + (cy - oy) * ny) / dn
            hx, hy = ox + t * dx - cx, oy + t * dy - cy
            along = hx * ux + hy * uy
            if t >= 0 and along >= 0 and along <= L and math.isfinite(t):
                best = min(best, t)
    for j in range(2):
        px, py = (ax, ay) if j == 0 else (bx, by)
        fx, fy = ox - px, oy - py
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - r * r
        disc = b * b - c
        if disc >= 0:
            t = -b - math.sqrt(disc)
            if t >= 0:
                best = min(best, t)
    return best


def maze_rays(walls, half, width, height, x, y, psi, n_rays, out):
    """Write into ``out`` (``(n_rays,)``) the distances along rays at ``psi + 2 pi k / n_rays``
    to the first wall surface or the image border; all 0 from inside a wall or outside the image."""
    if not (0 <= x <= width and 0 <= y <= height) or _clearance(walls, half, x, y) <= 0:
        for k in range(n_rays):
            out[k] = 0.0
        return out
    for k in range(n_rays):
        a = psi + 2.0 * np.pi * k / n_rays
        dx, dy = math.cos(a), math.sin(a)
        tx = (width - x) / dx if dx > 0 else (-x / dx if dx < 0 else np.inf)
        ty = (height - y) / dy if dy > 0 else (-y / dy if dy < 0 else np.inf)
        best = min(tx, ty)
        for w in range(walls.shape[0]):
            ax, ay, bx, by = walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
            # skip a wall whose bounding circle the ray misses or meets beyond the best so far
            # (a conservative test: the capsule lies inside that circle)
            cx, cy = 0.5 * (ax + bx) - x, 0.5 * (ay + by) - y
            rad = 0.5 * math.sqrt((bx - ax) ** 2 + (by - ay) ** 2) + half
            along = cx * dx + cy * dy
            if along < -rad or along - rad > best or abs(cx * dy - cy * dx) > rad:
                continue
            best = min(best, _ray_capsule(x, y, dx, dy, ax, ay, bx, by, half))
        out[k] = max(best, 0.0)
    return out


def maze_path_hit(walls, half, width, height, path):
    """Whether a path ``(S, 2+)`` has a point outside the image or inside a wall, or a segment
    between consecutive points touching a wall (distance <= half thickness)."""
    s = path.shape[0]
    lox, loy, hix, hiy = np.inf, np.inf, -np.inf, -np.inf
    for i in range(s):
        px, py = path[i, 0], path[i, 1]
        if not (0 <= px <= width and 0 <= py <= height):
            return True
        lox, loy, hix, hiy = min(lox, px), min(loy, py), max(hix, px), max(hiy, py)
    h2 = half * half
    for w in range(walls.shape[0]):
        ax, ay, bx, by = walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3]
        if min(ax, bx) - half > hix or max(ax, bx) + half < lox or min(ay, by) - half > hiy or max(ay, by) + half < loy:
            continue
        for i in range(s):
            if _seg_point_sq(ax, ay, bx, by, path[i, 0], path[i, 1]) <= h2:
                return True
        for i in range(s - 1):
            if _seg_seg_sq(path[i, 0], path[i, 1], path[i + 1, 0], path[i + 1, 1], ax, ay, bx, by) <= h2:
                return True
    return False


def dubins_path(x, y, psi, speed, u, duration, out, coef):
    """Write into ``out`` (``(S, 3)``) the poses at ``S`` equally spaced times over ``duration``
    of a constant-speed car holding turn rate ``u``: the closed forms of
    :meth:`rmm_envs.systems.maze.dynamics.Dubins3D.propagate` (``coef``: their series coefficients)."""
    s = out.shape[0]
    step = duration / (s - 1)
    for k in range(s):
        t = duration if k == s - 1 else k * step
        out[k, 0], out[k, 1] = segment_position(x, y, psi, speed, u, 0.0, t, coef)
        out[k, 2] = psi + u * t
    return out


def path_reaches_disc(path, cx, cy, r):
    """Whether a point of ``path`` or a segment between two of its points is within ``r`` of ``(cx, cy)``."""
    r2 = r * r
    for i in range(path.shape[0]):
        if (path[i, 0] - cx) ** 2 + (path[i, 1] - cy) ** 2 <= r2:
            return True
    for i in range(path.shape[0] - 1):
        if _seg_point_sq(path[i, 0], path[i, 1], path[i + 1, 0], path[i + 1, 1], cx, cy) <= r2:
            return True
    return False


if njit is not None:  # one source: the compiled kernels are these functions
    _seg_point_sq = njit(cache=True)(_seg_point_sq)
    _seg_seg_sq = njit(cache=True)(_seg_seg_sq)
    _clearance = njit(cache=True)(_clearance)
    _ray_capsule = njit(cache=True)(_ray_capsule)
    maze_rays = njit(cache=True)(maze_rays)
    maze_path_hit = njit(cache=True)(maze_path_hit)
    dubins_path = njit(cache=True)(dubins_path)
    path_reaches_disc = njit(cache=True)(path_reaches_disc)
