"""Compiled one-path failure tests that give the batched numpy tests' answers bit for bit.

The risk labeller's fused branch loops (:mod:`rmm_envs.scenes.branch_kernels`) test each path
right after computing it, one path at a time, instead of building every path of a tree level
and testing them as arrays.  To keep the labels the same bits, each test here repeats the
floating-point operations of its numpy twin in the same order (no fused multiply-adds: numba
contracts nothing without ``fastmath``), down to the pruning that decides which exact tests run:

* :func:`circle_path_hit`: :func:`rmm_envs.systems.dubins4d.circles.paths_hit_circles` for one path (the
  chord-midpoint pruning with the path length summed as numpy's pairwise ``sum`` does it, then
  the exact segment-circle test);
* :func:`maze_path_hit_near`: :meth:`rmm_envs.systems.maze.mazes.Maze.paths_hit` for one path, against
  the candidate walls of its first point's bucket (numpy's answer, including its limits: only
  those walls), with the same segment pruning.
"""

from __future__ import annotations

# Tests hold each to its numpy twin on random paths and on the labels' own trees
# (``tests/test_fused_labels.py``).
import math
from collections.abc import Callable
from typing import Any

from rmm_envs.systems.maze.maze_kernels import _seg_point_sq, _seg_seg_sq

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; plain Python still works
    njit = None

__all__ = ["circle_path_hit", "maze_path_hit_near", "pairwise_sum"]

_PW_BLOCKSIZE = 128  # numpy's pairwise summation block (numpy/_core/src/umath/loops_utils.h.src)


def pairwise_sum(a, n):
    """The sum of ``a[:n]`` as numpy's ``add.reduce`` of a contiguous row adds it (its pairwise
    summation: eight running sums over blocks of up to 128 numbers, halves above that), so the
    result has numpy's bits; a test compares it with ``np.sum`` for lengths 1-1000."""
    if n < 8:
        res = -0.0
        for i in range(n):
            res += a[i]
        return res
    if n <= _PW_BLOCKSIZE:
        r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
        i = 8
        while i < n - (n % 8):
            r0 += a[i]
            r1 += a[i + 1]
            r2 += a[i + 2]
            r3 += a[i + 3]
            r4 += a[i + 4]
            r5 += a[i + 5]
            r6 += a[i + 6]
            r7 += a[i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return pairwise_sum(a[:n2], n2) + pairwise_sum(a[n2:n], n - n2)


def circle_path_hit(px, py, n, circles, seg_len):
    """Whether the path of points ``(px[i], py[i])``, ``i < n``, touches a circle of ``circles``
    ``(K, 3)``: :func:`~rmm_envs.systems.dubins4d.circles.paths_hit_circles` for one path.  ``seg_len``: a
    scratch array of at least ``n - 1`` floats."""
    if circles.shape[0] == 0 or n == 0:
        return False
    if n == 1:  # numpy's points_in_circles
        for k in range(circles.shape[0]):
            dx, dy = px[0] - circles[k, 0], py[0] - circles[k, 1]
            if dx * dx + dy * dy <= circles[k, 2] * circles[k, 2]:
                return True
        return False
    for j in range(n - 1):
        dx, dy = px[j + 1] - px[j], py[j + 1] - py[j]
        seg_len[j] = math.sqrt(dx * dx + dy * dy)
    half_len = 0.5 * pairwise_sum(seg_len, n - 1)
    mx, my = 0.5 * (px[0] + px[n - 1]), 0.5 * (py[0] + py[n - 1])
    for k in range(circles.shape[0]):
        cx, cy, r = circles[k, 0], circles[k, 1], circles[k, 2]
        dmx, dmy = mx - cx, my - cy
        reach = r + half_len
        if not (dmx * dmx + dmy * dmy <= reach * reach):
            continue
        r2 = r * r
        for j in range(n - 1):
            dx, dy = px[j + 1] - px[j], py[j + 1] - py[j]
            fx, fy = cx - px[j], cy - py[j]
            dd = dx * dx + dy * dy
            fd = fx * dx + fy * dy
            s = min(max(fd / dd, 0.0), 1.0) if dd > 0 else 0.0
            gx, gy = fx - s * dx, fy - s * dy
            if gx * gx + gy * gy <= r2:
                return True
    return False


def maze_path_hit_near(px, py, n, walls, cand, half, width, height, d2):
    """Whether the path of points ``(px[i], py[i])``, ``i < n``, fails in a maze:
    :meth:`~rmm_envs.systems.maze.mazes.Maze.paths_hit` for one path.  ``walls``: the maze's extended
    wall array (``Maze._walls_ext``, a far dummy wall last); ``cand``: the indices of the
    candidate walls (``Maze._candidates`` of the path's first point); ``d2``: a scratch array of
    at least ``n * len(cand)`` floats."""
    for i in range(n):
        if not (px[i] >= 0 and px[i] <= width and py[i] >= 0 and py[i] <= height):
            return True
    h2 = half * half
    m = cand.shape[0]
    for k in range(m):
        w = cand[k]
        for i in range(n):
            d = _seg_point_sq(walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3], px[i], py[i])
            if d <= h2:
                return True
            d2[i * m + k] = d
    for j in range(n - 1):
        dx, dy = px[j + 1] - px[j], py[j + 1] - py[j]
        reach = half + math.sqrt(dx * dx + dy * dy)
        lim = reach * reach
        for k in range(m):
            if min(d2[j * m + k], d2[(j + 1) * m + k]) <= lim:
                w = cand[k]
                dd = _seg_seg_sq(px[j], py[j], px[j + 1], py[j + 1], walls[w, 0], walls[w, 1], walls[w, 2], walls[w, 3])
                if dd <= h2:
                    return True
    return False


if njit is not None:  # one source: the compiled kernels are these functions
    pairwise_sum = njit(cache=True)(pairwise_sum)
    circle_path_hit = njit(cache=True)(circle_path_hit)
    maze_path_hit_near = njit(cache=True)(maze_path_hit_near)
