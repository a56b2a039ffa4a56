"""A map of your own: obstacle shapes, an optional goal and start box, read from JSON.

The format's user spec is the ``Map format`` section of :mod:`rmm_envs.systems.dubins4d_map.env`; this
module checks it and builds :class:`ShapeMap`: a JSON list of ``circle``, ``polygon``,
``segment``, ``goal`` and ``start`` entries (or an object with ``shapes``, ``goal`` and
``start``), at least one obstacle, every number finite and at most ``1e9`` in magnitude, a
file of at most 16 MiB.  A bad map raises :class:`MapError` (a ``ValueError``) naming the entry
by its index and content and saying what was expected; an unreadable or non-JSON file raises it
naming the file.  Shapes are kept exactly as given; :func:`triangulate` splits a polygon into
triangles for engines that need convex pieces.  Each entry's rules and the limits (a polygon of
at most 5,000 vertices, checked before the rest is read): the ``Map format`` section above.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rmm_envs.machine_independent import dot
from rmm_envs.worlds.bounds import MAX_MAGNITUDE, MAX_MAP_BYTES, MAX_POLYGON_VERTICES, within_bounds

__all__ = ["OBSTACLE_SHAPES", "MapError", "ShapeMap", "load_map", "triangulate"]

OBSTACLE_SHAPES = ("circle", "polygon", "segment")
_ENTRY_KEYS = OBSTACLE_SHAPES + ("goal", "start")


class MapError(ValueError):
    """A map that cannot be used; the message names the entry (index and content) or the file."""


def _show(entry: Any, limit: int = 120) -> str:
    try:
        text = json.dumps(entry)
    except (TypeError, ValueError):
        text = repr(entry)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)


def _numbers(value, n: int, what: str) -> np.ndarray:
    """``value`` as ``n`` finite floats, else ``ValueError(what)``."""
    if not isinstance(value, (list, tuple)) or len(value) != n or not all(_number(v) for v in value):
        raise ValueError(f"expected {what}")
    if not all(isinstance(v, (int, np.integer)) or math.isfinite(v) for v in value):
        raise ValueError(f"expected {what} with finite numbers (no NaN or infinity)")
    if not within_bounds(list(value)):  # before converting: 10**400 would overflow
        raise ValueError(
            f"expected {what} with numbers of magnitude at most {MAX_MAGNITUDE:g} (larger ones overflow the geometry)"
        )
    return np.array(value, dtype=float)


def _point(value, what: str) -> np.ndarray:
    return _numbers(value, 2, what)


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _on_segment(p, q, r) -> bool:
    """``q`` (collinear with ``p``-``r``) lies within their bounding box."""
    return min(p[0], r[0]) <= q[0] <= max(p[0], r[0]) and min(p[1], r[1]) <= q[1] <= max(p[1], r[1])


def _segments_meet(p1, p2, q1, q2) -> bool:
    """Whether closed segments ``p1p2`` and ``q1q2`` share a point (touching counts)."""
    d1, d2 = _cross(q1, q2, p1), _cross(q1, q2, p2)
    d3, d4 = _cross(p1, p2, q1), _cross(p1, p2, q2)
    if ((d1 > 0 > d2) or (d1 < 0 < d2)) and ((d3 > 0 > d4) or (d3 < 0 < d4)):
        return True
    return (
        (d1 == 0 and _on_segment(q1, p1, q2))
        or (d2 == 0 and _on_segment(q1, p2, q2))
        or (d3 == 0 and _on_segment(p1, q1, p2))
        or (d4 == 0 and _on_segment(p1, q2, p2))
    )


def _cross_many(o, a, b) -> np.ndarray:
    """:func:`_cross` with ``o``, ``a`` or ``b`` arrays of points ``(K, 2)``: the same operations, elementwise."""
    o, a, b = np.asarray(o), np.asarray(a), np.asarray(b)
    return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])


def _on_segment_many(p, q, r) -> np.ndarray:
    return (
        (np.minimum(p[..., 0], r[..., 0]) <= q[..., 0])
        & (q[..., 0] <= np.maximum(p[..., 0], r[..., 0]))
        & (np.minimum(p[..., 1], r[..., 1]) <= q[..., 1])
        & (q[..., 1] <= np.maximum(p[..., 1], r[..., 1]))
    )


def _segments_meet_many(p1, p2, q1, q2) -> np.ndarray:
    """:func:`_segments_meet` of one segment ``p1p2`` against segments ``q1[k]q2[k]``, ``(K,)`` bool:
    the same tests, vectorised (a polygon of thousands of vertices is checked in seconds)."""
    p1b, p2b = np.broadcast_to(p1, q1.shape), np.broadcast_to(p2, q1.shape)
    d1, d2 = _cross_many(q1, q2, p1b), _cross_many(q1, q2, p2b)
    d3, d4 = _cross_many(p1b, p2b, q1), _cross_many(p1b, p2b, q2)
    proper = (((d1 > 0) & (0 > d2)) | ((d1 < 0) & (0 < d2))) & (((d3 > 0) & (0 > d4)) | ((d3 < 0) & (0 < d4)))
    return (
        proper
        | ((d1 == 0) & _on_segment_many(q1, p1b, q2))
        | ((d2 == 0) & _on_segment_many(q1, p2b, q2))
        | ((d3 == 0) & _on_segment_many(p1b, q1, p2b))
        | ((d4 == 0) & _on_segment_many(p1b, q2, p2b))
    )


def _polygon(value) -> np.ndarray:
    what = "a list of at least 3 [x, y] vertices"
    if not isinstance(value, (list, tuple)):
        raise ValueError(f"expected {what}")
    if len(value) > MAX_POLYGON_VERTICES + 1:  # + 1: a closed ring repeats its first vertex
        raise ValueError(
            f"expected at most {MAX_POLYGON_VERTICES:,} vertices, got {len(value):,}; split the outline "
            "into several polygons"
        )
    pts = [_point(v, f"{what}; vertex {i} is not [x, y]") for i, v in enumerate(value)]
    if len(pts) >= 2 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]  # a closed ring: the repeated first vertex is dropped
    if len(pts) < 3:
        raise ValueError(f"expected {what}, got {len(pts)} distinct vertices")
    v = np.array(pts)
    n = len(v)
    for i in range(n):
        if np.array_equal(v[i], v[(i + 1) % n]):
            raise ValueError(f"vertices {i} and {(i + 1) % n} are the same point {v[i].tolist()}")
    ends = np.roll(v, -1, axis=0)  # edge k runs from v[k] to ends[k]

    def fold(i: int, j: int) -> None:  # neighbours share a vertex: they must not fold back onto each other
        a, b, c, d = v[i], ends[i], v[j], ends[j]
        shared, p, q = (b, a, d) if j == i + 1 else (a, b, c)
        if _cross(shared, p, q) == 0 and dot(p - shared, q - shared) > 0:
            raise ValueError(
                f"edges {i} and {j} overlap (the outline folds back at vertex "
                f"{(i + 1) % n if j == i + 1 else 0}); a polygon must be simple"
            )

    for i in range(n):  # pairs in the order (i, j > i), each edge against all later ones at once
        if i + 1 < n:
            fold(i, i + 1)
        last = n - 1 if i == 0 else n  # edge 0 and edge n - 1 are neighbours too
        if i + 2 < last:
            js = np.arange(i + 2, last)
            meet = _segments_meet_many(v[i], ends[i], v[js], ends[js])
            if meet.any():
                j = int(js[np.argmax(meet)])
                a, b, c, d = v[i], ends[i], v[j], ends[j]
                raise ValueError(
                    f"edges {i} ({a.tolist()} to {b.tolist()}) and {j} ({c.tolist()} to {d.tolist()}) "
                    "cross or touch; a polygon must be simple (non-self-intersecting)"
                )
        if i == 0 and n - 1 > 1:
            fold(0, n - 1)
    area = 0.5 * float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
    if area == 0:  # pragma: no cover - a simple polygon has an area (collinear ones fold back, above)
        raise ValueError("the polygon has zero area (all vertices on one line)")
    return v if area > 0 else v[::-1].copy()  # counter-clockwise


def _segment(value) -> tuple[np.ndarray, np.ndarray, float]:
    what = "[[x0, y0], [x1, y1], thickness]"
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise ValueError(f"expected {what}")
    a, b = (
        _point(value[0], f"{what}; the first end is not [x, y]"),
        _point(value[1], f"{what}; the second end is not [x, y]"),
    )
    if not _number(value[2]) or not within_bounds(value[2]) or value[2] <= 0:
        raise ValueError(
            f"expected {what} with a finite thickness > 0 of at most {MAX_MAGNITUDE:g}, got thickness "
            f"{str(value[2])[:40]}"
        )
    if np.array_equal(a, b):
        raise ValueError("the segment's ends are the same point; use a circle for a disc")
    return a, b, float(value[2])


def _circle(value, what: str = "[x, y, r] with r > 0") -> np.ndarray:
    c = _numbers(value, 3, what)
    if c[2] <= 0:
        raise ValueError(f"expected {what}, got r = {c[2]:g}")
    return c


def _box(value) -> np.ndarray:
    what = "[[x_min, y_min], [x_max, y_max]] with x_min < x_max and y_min < y_max"
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ValueError(f"expected {what}")
    lo, hi = _point(value[0], what), _point(value[1], what)
    if not (lo[0] < hi[0] and lo[1] < hi[1]):
        raise ValueError(f"expected {what}")
    return np.array([lo, hi])


@dataclass
class ShapeMap:
    """A checked map: its obstacles (in the order given) and the optional goal and start box.

    ``circles`` ``(K_c, 3)``, ``polygons`` (counter-clockwise ``(V, 2)`` arrays), ``segments``
    ``(a, b, thickness)``; ``entries`` pairs each obstacle, in map order, with its shape and its
    index in the source list; ``goal`` ``(3,)`` or ``None``; ``start_box``
    ``[[x_min, y_min], [x_max, y_max]]`` (the bounding box of the map when not given).
    """

    circles: np.ndarray
    polygons: list = field(default_factory=list)
    segments: list = field(default_factory=list)
    goal: np.ndarray | None = None
    start_box: np.ndarray | None = None
    entries: list = field(default_factory=list)  # (shape, index in the source list, index among that shape's)
    source: str = "<map>"

    @property
    def obstacle_shapes(self) -> tuple[str, ...]:
        """The obstacle shapes present, in :data:`OBSTACLE_SHAPES` order."""
        have = {k for k, _, _ in self.entries}
        return tuple(k for k in OBSTACLE_SHAPES if k in have)

    @property
    def circles_only(self) -> bool:
        return self.obstacle_shapes == ("circle",)

    def bounding_box(self) -> np.ndarray:
        """``[[x_min, y_min], [x_max, y_max]]`` of every obstacle and the goal."""
        pts = [self.circles[:, :2] - self.circles[:, 2:3], self.circles[:, :2] + self.circles[:, 2:3]]
        pts += list(self.polygons)
        for a, b, t in self.segments:
            pts += [np.array([a, b]) - t / 2, np.array([a, b]) + t / 2]
        if self.goal is not None:
            pts += [self.goal[None, :2] - self.goal[2], self.goal[None, :2] + self.goal[2]]
        allp = np.vstack([p.reshape(-1, 2) for p in pts])
        return np.array([allp.min(axis=0), allp.max(axis=0)])

    def to_json(self) -> list:
        """The map as a list of entries (obstacles in order, then goal and start), loadable again."""
        out: list = []
        for shape, _, k in self.entries:
            if shape == "circle":
                out.append({"circle": self.circles[k].tolist()})
            elif shape == "polygon":
                out.append({"polygon": self.polygons[k].tolist()})
            else:
                a, b, t = self.segments[k]
                out.append({"segment": [a.tolist(), b.tolist(), t]})
        if self.goal is not None:
            out.append({"goal": self.goal.tolist()})
        assert self.start_box is not None  # load_map sets it (the bounding box when the map gives none)
        out.append({"start": self.start_box.tolist()})
        return out


def _entries(data, source: str) -> list[tuple[str, Any]]:
    """``(name, entry)`` pairs of a loaded map, ``name`` saying where the entry is."""
    if isinstance(data, dict):
        unknown = sorted(set(data) - {"shapes", "goal", "start"})
        if unknown or "shapes" not in data:
            raise MapError(
                f"map {source}: an object map needs the key 'shapes' (a list of entries) and may have "
                f"'goal' and 'start'; got keys {sorted(data)}"
            )
        shapes = data["shapes"]
        if not isinstance(shapes, (list, tuple)):
            raise MapError(f"map {source}: 'shapes' must be a list of entries, got {_show(shapes)}")
        out = [(f"shapes[{i}]", e) for i, e in enumerate(shapes)]
        out += [(k, {k: data[k]}) for k in ("goal", "start") if k in data]
        return out
    if isinstance(data, (list, tuple)):
        return [(f"entry {i}", e) for i, e in enumerate(data)]
    raise MapError(
        f"map {source}: expected a list of entries (or an object with 'shapes'), got {type(data).__name__} "
        f"{_show(data)}"
    )


def load_map(map_spec) -> ShapeMap:
    """A :class:`ShapeMap` from a JSON file path (``str`` or ``os.PathLike``), or from the
    list (or object) already loaded; :class:`MapError` naming the file or the bad entry."""
    if isinstance(map_spec, ShapeMap):
        return map_spec
    if isinstance(map_spec, (str, os.PathLike)):
        source = repr(str(map_spec))
        try:
            with open(map_spec, "rb") as fh:
                raw = fh.read(MAX_MAP_BYTES + 1)  # never more: a device such as /dev/zero has no end
            if len(raw) > MAX_MAP_BYTES:
                raise MapError(
                    f"map file {source} holds more than {MAX_MAP_BYTES // 2**20} MiB; a map is a short JSON "
                    "list of shapes"
                )
            text = raw.decode("utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise MapError(f"map file {source} cannot be read: {type(e).__name__}: {e}") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise MapError(f"map file {source} is not valid JSON: {e}") from None
        except RecursionError:
            raise MapError(
                f"map file {source} nests its JSON too deeply; a map is a list of shapes, each a few levels deep"
            ) from None
        except ValueError as e:  # an integer literal of thousands of digits
            raise MapError(f"map file {source} holds a number that cannot be read: {e}") from None
    else:
        source, data = "(given as data)", map_spec
    circles: list[np.ndarray] = []
    polygons: list[np.ndarray] = []
    segments: list[tuple[np.ndarray, np.ndarray, float]] = []
    entries: list[tuple[str, int, int]] = []
    goal = start = None
    for index, (name, entry) in enumerate(_entries(data, source)):
        where = f"map {source}, {name} {_show(entry)}"
        if not isinstance(entry, dict) or len(entry) != 1:
            raise MapError(f"{where}: an entry must be an object with exactly one key, one of {list(_ENTRY_KEYS)}")
        ((shape, value),) = entry.items()
        if shape not in _ENTRY_KEYS:
            raise MapError(f"{where}: unknown shape {shape!r}; expected one of {list(_ENTRY_KEYS)}")
        try:
            if shape == "circle":
                entries.append((shape, index, len(circles)))
                circles.append(_circle(value))
            elif shape == "polygon":
                entries.append((shape, index, len(polygons)))
                polygons.append(_polygon(value))
            elif shape == "segment":
                entries.append((shape, index, len(segments)))
                segments.append(_segment(value))
            elif shape == "goal":
                if goal is not None:
                    raise ValueError("a second goal; a map has at most one")
                goal = _circle(value, "[x, y, r] with r > 0 (the goal disc)")
            else:
                if start is not None:
                    raise ValueError("a second start box; a map has at most one")
                start = _box(value)
        except ValueError as e:
            raise MapError(f"{where}: {e}") from None
    if not entries:
        raise MapError(f"map {source} has no obstacle: it needs at least one of {list(OBSTACLE_SHAPES)}")
    m = ShapeMap(np.array(circles, dtype=float).reshape(-1, 3), polygons, segments, goal, None, entries, source)
    m.start_box = start if start is not None else m.bounding_box()
    return m


def triangulate(polygon: np.ndarray) -> list[np.ndarray]:
    """Triangles ``(3, 2)`` covering a simple counter-clockwise polygon exactly (ear clipping).

    Vertices on a straight line between their neighbours are dropped first (they change no
    point of the polygon), so every triangle has a positive area.  Each candidate ear is tested
    against all other vertices at once (a polygon of thousands of vertices takes seconds).
    """
    v = np.array(polygon, dtype=float).reshape(-1, 2)
    tris = []
    while len(v) > 3:
        n = len(v)
        prev, nxt = np.roll(v, 1, axis=0), np.roll(v, -1, axis=0)
        turn = _cross_many(prev, v, nxt)
        flat = np.flatnonzero(turn == 0)
        if flat.size:  # a vertex on the line between its neighbours: dropping it changes nothing
            v = np.delete(v, flat[0], axis=0)
            continue
        for i in np.flatnonzero(turn > 0):  # reflex corners (turn < 0) are no ears
            a, b, c = prev[i], v[i], nxt[i]
            others = np.ones(n, dtype=bool)
            others[[(i - 1) % n, i, (i + 1) % n]] = False
            p = v[others]
            if np.any((_cross_many(a, b, p) >= 0) & (_cross_many(b, c, p) >= 0) & (_cross_many(c, a, p) >= 0)):
                continue  # another vertex inside or on it
            tris.append(np.array([a, b, c]))
            v = np.delete(v, i, axis=0)
            break
        else:  # pragma: no cover - a simple polygon always has an ear (two, in fact)
            raise MapError("polygon could not be triangulated; is it simple?")
    tris.append(v.copy())
    return tris
