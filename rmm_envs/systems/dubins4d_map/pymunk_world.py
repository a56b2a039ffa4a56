"""A :class:`~rmm_envs.systems.dubins4d_map.shape_map.ShapeMap`'s obstacles in a pymunk space: rays, point and path tests.

Every obstacle becomes static pymunk shapes (a circle, a segment of radius ``thickness / 2``,
a polygon's ear-clipping triangles), and questions are answered by pymunk's spatial queries
with the conventions of :mod:`rmm_envs.systems.dubins4d.circles`: a point is **inside** at distance
``<= 0``; a **ray** reads the distance to the first shape up to ``max_range`` (0 from inside an
obstacle); a path's **contact parameter** is ``0`` when its first point is inside, else
``j + s`` for the first segment ``j`` entering an obstacle at fraction ``s``, ``inf`` when it
never touches one.  On a map of circles only the answers agree with the analytic circle
functions to rounding (tested to 1e-4).

The queries in detail and the bounding-box shortcut: :class:`PymunkWorld`.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np

from rmm_envs.systems.dubins4d_map.shape_map import ShapeMap, triangulate

__all__ = ["PymunkWorld", "require_pymunk"]

#: point queries look this far past a boundary so that a point exactly on it (distance 0) is
#: found (pymunk keeps only shapes strictly nearer than the query's maximum distance)
_REACH = 1e-6


def require_pymunk():
    """The ``pymunk`` module, or a ``DependencyNotInstalled`` error saying how to install it."""
    try:  # lazy: pymunk is an optional dependency (the map extra)
        import pymunk
    except ImportError as e:
        raise gym.error.DependencyNotInstalled(
            "maps of your own need pymunk: the map extra, pip install -e '.[map]' in a clone"
        ) from e
    return pymunk


class PymunkWorld:
    """The obstacles of ``shape_map`` in a static pymunk space (see the module docstring).

    A circle becomes a ``pymunk.Circle``, a segment a ``pymunk.Segment`` of radius
    ``thickness / 2`` (a capsule), a polygon its ear-clipping triangles (``pymunk.Poly``: pymunk's
    polygons are convex).  A point is inside when ``point_query_nearest`` finds a shape at
    distance ``<= 0``; a ray is ``segment_query_first`` from the origin to ``max_range``; a
    path's contact parameter needs no point query beyond its first point (a path becomes inside
    only by crossing a boundary, which ``segment_query_first`` finds).  Before any pymunk call a
    query is skipped when its bounding box meets no obstacle's (numpy for batches, pymunk's
    ``bb_query`` for one path), so free space costs almost nothing."""

    def __init__(self, shape_map: ShapeMap) -> None:
        pymunk = require_pymunk()
        self.map = shape_map
        self.space = pymunk.Space()
        body = self.space.static_body
        shapes = []
        for shape, _, k in shape_map.entries:
            if shape == "circle":
                x, y, r = shape_map.circles[k]
                shapes.append(pymunk.Circle(body, float(r), (float(x), float(y))))
            elif shape == "segment":
                a, b, t = shape_map.segments[k]
                shapes.append(pymunk.Segment(body, tuple(map(float, a)), tuple(map(float, b)), t / 2.0))
            else:
                shapes += [
                    pymunk.Poly(body, [tuple(map(float, p)) for p in tri]) for tri in triangulate(shape_map.polygons[k])
                ]
        self.space.add(*shapes)
        self.shapes = shapes
        self._filter = pymunk.ShapeFilter()
        self._BB = pymunk.BB
        # every shape's bounding box [left, bottom, right, top], for the numpy pre-filter
        self.bbs = np.array([[bb.left, bb.bottom, bb.right, bb.top] for bb in (sh.cache_bb() for sh in shapes)])

    # ------------------------------------------------------------------ pre-filters
    def _near(self, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: box ``[lo, hi]`` (``(N, 2)`` each) meets some shape's bounding box."""
        b = self.bbs
        return np.any(
            (lo[:, None, 0] <= b[None, :, 2])
            & (hi[:, None, 0] >= b[None, :, 0])
            & (lo[:, None, 1] <= b[None, :, 3])
            & (hi[:, None, 1] >= b[None, :, 1]),
            axis=1,
        )

    def _inside(self, x: float, y: float) -> bool:
        info = self.space.point_query_nearest((x, y), _REACH, self._filter)
        return info is not None and info.distance <= 0.0

    # ------------------------------------------------------------------ queries
    def points_inside(self, points: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: point ``i`` (``(N, 2+)``) lies in (or on) an obstacle."""
        pts = np.asarray(points, dtype=float)[:, :2]
        if pts.shape[0] == 1:  # one point (a start being drawn): pymunk's own tree, no numpy set-up
            return np.array([self._inside(float(pts[0, 0]), float(pts[0, 1]))])
        out = np.zeros(pts.shape[0], dtype=bool)
        for i in np.flatnonzero(self._near(pts - _REACH, pts + _REACH)):
            out[i] = self._inside(pts[i, 0], pts[i, 1])
        return out

    def rays(self, origins: np.ndarray, headings: np.ndarray, n_rays: int = 12, max_range: float = 10.0) -> np.ndarray:
        """``(N, n_rays)`` distances to the nearest obstacle along ray ``i`` at ``heading + 2 pi i /
        n_rays``, capped at ``max_range``; 0 from inside an obstacle."""
        o = np.asarray(origins, dtype=float)[:, :2]
        h = np.asarray(headings, dtype=float).reshape(o.shape[0])
        out = np.full((o.shape[0], int(n_rays)), float(max_range))
        step = 2.0 * math.pi / n_rays
        query = self.space.segment_query_first
        for i in np.flatnonzero(self._near(o - max_range, o + max_range)):
            x, y = float(o[i, 0]), float(o[i, 1])
            if self._inside(x, y):
                out[i] = 0.0
                continue
            for r in range(int(n_rays)):
                a = h[i] + step * r
                info = query((x, y), (x + max_range * math.cos(a), y + max_range * math.sin(a)), 0.0, self._filter)
                if info is not None:
                    out[i, r] = info.alpha * max_range
        return out

    def _path_contact(self, xy: np.ndarray) -> float:
        if self._inside(xy[0, 0], xy[0, 1]):
            return 0.0
        query = self.space.segment_query_first
        pts = xy.tolist()
        for j in range(len(pts) - 1):
            info = query(tuple(pts[j]), tuple(pts[j + 1]), 0.0, self._filter)
            if info is not None:
                return j + info.alpha
        return math.inf

    def first_contacts(self, paths: np.ndarray) -> np.ndarray:
        """``(N,)`` contact parameters of paths ``(N, S, 2+)`` with the obstacles (``inf``: none)."""
        xy = np.asarray(paths, dtype=float)[:, :, :2]
        out = np.full(xy.shape[0], math.inf)
        if xy.shape[0] == 1:  # an env step: one pymunk bounding-box query instead of numpy's set-up
            lo, hi = xy[0].min(axis=0), xy[0].max(axis=0)
            bb = self._BB(lo[0] - _REACH, lo[1] - _REACH, hi[0] + _REACH, hi[1] + _REACH)
            if self.space.bb_query(bb, self._filter):
                out[0] = self._path_contact(xy[0])
            return out
        for i in np.flatnonzero(self._near(xy.min(axis=1) - _REACH, xy.max(axis=1) + _REACH)):
            out[i] = self._path_contact(xy[i])
        return out

    def paths_hit(self, paths: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: any point or segment of path ``i`` touches an obstacle."""
        return np.isfinite(self.first_contacts(paths))
