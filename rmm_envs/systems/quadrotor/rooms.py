"""Procedurally generated rooms for the quadrotor (docs/original-code.md, item 26), from primitives only.

A room is a **footprint** (the union of 1-32 overlapping axis-aligned rectangles), **walls**
of thickness 0.5 m around it, a **floor** (the plane z = 0, which counts as an obstacle) and
0-50 each of **boxes**, **cylinders** and **spheres** with random orientations, resting on the
floor inside the footprint and not overlapping one another.  No Blender, no convex
decomposition: every shape is a PyBullet primitive.  :func:`build_room` creates the bodies in a
PyBullet client; the arrays here are the geometry for everything else.

The distributions of every part: :func:`generate_room`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rmm_envs.machine_independent import dot, norm
from rmm_envs.systems.quadrotor.rotations import quat_from_euler, quat_to_rot

__all__ = ["Room", "bounding_radius", "build_room", "generate_room"]


@dataclass
class Room:
    """Geometry of one room (metres).

    ``cell``: the footprint grid's cell size; ``origin``: its lower-left corner;
    ``footprint``: ``(nx, ny)`` bool; ``walls``: ``(W, 6)`` boxes ``(cx, cy, cz, hx, hy, hz)``;
    ``objects``: list of dicts ``{"shape", "pos", "quat", "size"}`` (``size``: half extents for
    boxes, ``(radius, length)`` for cylinders, ``(radius,)`` for spheres).
    """

    footprint: np.ndarray
    origin: np.ndarray
    cell: float
    wall_height: float
    walls: np.ndarray
    objects: list = field(default_factory=list)

    def in_footprint(self, xy: np.ndarray) -> np.ndarray:
        xy = np.atleast_2d(np.asarray(xy, float))
        ij = np.floor((xy - self.origin) / self.cell).astype(int)
        nx, ny = self.footprint.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
        out = np.zeros(xy.shape[0], dtype=bool)
        out[ok] = self.footprint[ij[ok, 0], ij[ok, 1]]
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = self.walls[:, :3] - self.walls[:, 3:]
        hi = self.walls[:, :3] + self.walls[:, 3:]
        return lo.min(axis=0), hi.max(axis=0)


def _footprint_rects(rng, n, X, Y):
    rects = []
    tries = 0
    while len(rects) < n and tries < 10_000:
        tries += 1
        cx, cy = rng.uniform(-X / 2, X / 2), rng.uniform(-Y / 2, Y / 2)
        w, h = max(2.0, rng.uniform(0, 1) * 10), max(2.0, rng.uniform(0, 1) * 10)
        r = (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)
        if rects and not any(r[0] < q[2] and q[0] < r[2] and r[1] < q[3] and q[1] < r[3] for q in rects):
            continue
        rects.append(r)
    return rects


def bounding_radius(shape: str, size) -> float:
    """The radius of the sphere about an object's centre that holds it in any orientation: a
    box's half diagonal (``size``: half extents), a cylinder's (``size``: radius, length) or a
    sphere's radius.  The room generator spaces objects by it, the collision check and the
    quadrotor ``hj`` cull by it."""
    if shape == "box":
        return norm(size)
    if shape == "cylinder":
        return float(np.hypot(size[0], size[1] / 2))
    return float(size[0])


def generate_room(
    rng: np.random.Generator,
    n_rectangles: int | None = None,
    x_range: float | None = None,
    y_range: float | None = None,
    wall_height: float | None = None,
    n_boxes: int | None = None,
    n_cylinders: int | None = None,
    n_spheres: int | None = None,
    wall_thickness: float = 0.5,
) -> Room:
    """A seeded random room; any argument left ``None`` is drawn as below.  A given argument must
    be an integer (the counts: ``n_rectangles >= 1``, the object counts ``>= 0``) or a finite
    length in metres ``> 0``; anything else is refused (``ValueError`` naming it) before anything
    is drawn.

    * **footprint**: the union of ``n_rectangles`` (1-32) axis-aligned rectangles with centres
      uniform on ``[-X/2, X/2] x [-Y/2, Y/2]`` (``X, Y ~ U(5, 50)`` m), sides ``max(2, U(0, 10))``
      m, each new rectangle kept only if it overlaps the union so far (as pcg_gazebo did);
    * **walls** of thickness 0.5 m and height ``U(0.1, 5)`` m around it, built on a grid of
      wall-thickness cells: every cell outside the footprint that touches it (8-neighbourhood) is
      wall, merged row by row into boxes;
    * a **floor** (the plane z = 0, which counts as an obstacle);
    * 0-50 each of **boxes** (sides ``U(0.1, 1)`` m), **cylinders** (radius and length
      ``U(0.1, 1)`` m) and **spheres** (radius ``U(0.1, 1)`` m), with random roll, pitch and yaw,
      resting on the floor inside the footprint and not overlapping one another (their bounding
      spheres are kept apart)."""
    for name, v, lo in (
        ("n_rectangles", n_rectangles, 1),
        ("n_boxes", n_boxes, 0),
        ("n_cylinders", n_cylinders, 0),
        ("n_spheres", n_spheres, 0),
    ):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo):
            raise ValueError(f"generate_room: {name} must be an integer >= {lo}, got {v!r}")
    for name, length in (
        ("x_range", x_range),
        ("y_range", y_range),
        ("wall_height", wall_height),
        ("wall_thickness", wall_thickness),
    ):
        if length is not None and (
            isinstance(length, bool)
            or not isinstance(length, (int, float, np.number))
            or not math.isfinite(length)
            or length <= 0
        ):
            raise ValueError(f"generate_room: {name} must be a finite number of metres > 0, got {length!r}")
    n = int(rng.integers(1, 33)) if n_rectangles is None else int(n_rectangles)
    X = float(rng.uniform(5, 50)) if x_range is None else float(x_range)
    Y = float(rng.uniform(5, 50)) if y_range is None else float(y_range)
    H = float(rng.uniform(0.1, 5.0)) if wall_height is None else float(wall_height)
    counts = [int(rng.integers(0, 51)) if c is None else int(c) for c in (n_boxes, n_cylinders, n_spheres)]
    rects = np.array(_footprint_rects(rng, n, X, Y))
    c = wall_thickness
    lo = rects[:, :2].min(axis=0) - 2 * c
    hi = rects[:, 2:].max(axis=0) + 2 * c
    nx, ny = (np.ceil((hi - lo) / c)).astype(int)
    xs = lo[0] + (np.arange(nx) + 0.5) * c
    ys = lo[1] + (np.arange(ny) + 0.5) * c
    X_, Y_ = np.meshgrid(xs, ys, indexing="ij")
    foot = np.zeros((nx, ny), dtype=bool)
    for x0, y0, x1, y1 in rects:
        foot |= (X_ >= x0) & (X_ <= x1) & (Y_ >= y0) & (Y_ <= y1)
    grow = foot.copy()
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            grow |= np.roll(np.roll(foot, dx, axis=0), dy, axis=1)
    wall = grow & ~foot
    boxes = []
    for i in range(nx):  # merge runs along y into boxes
        j = 0
        while j < ny:
            if wall[i, j]:
                k = j
                while k + 1 < ny and wall[i, k + 1]:
                    k += 1
                y0, y1 = lo[1] + j * c, lo[1] + (k + 1) * c
                boxes.append((lo[0] + (i + 0.5) * c, 0.5 * (y0 + y1), H / 2, c / 2, 0.5 * (y1 - y0), H / 2))
                j = k + 1
            else:
                j += 1
    room = Room(footprint=foot, origin=lo, cell=c, wall_height=H, walls=np.array(boxes))

    placed: list[tuple[np.ndarray, float]] = []
    placed_xy, placed_r = np.empty((sum(counts), 2)), np.empty(sum(counts))
    objects = []
    inner = foot.copy()  # keep objects a cell away from the walls
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            inner &= np.roll(np.roll(foot, dx, axis=0), dy, axis=1)
    free_cells = np.argwhere(inner)
    for shape, count in zip(("box", "cylinder", "sphere"), counts, strict=True):
        for _ in range(count):
            for _try in range(50):
                if shape == "box":
                    size = rng.uniform(0.1, 1.0, 3) / 2
                elif shape == "cylinder":
                    size = np.array([rng.uniform(0.1, 1.0), rng.uniform(0.1, 1.0)])
                else:
                    size = np.array([rng.uniform(0.1, 1.0)])
                angles = rng.uniform(-np.pi, np.pi, 3)
                # the footprint radius does not depend on the orientation: rotate only a kept object
                radius = bounding_radius(shape, size)
                if free_cells.size == 0:
                    break
                cell_ij = free_cells[rng.integers(len(free_cells))]
                xy = lo + (cell_ij + rng.uniform(0, 1, 2)) * c
                if placed:  # exact norms only where the per-axis gaps allow an overlap
                    near = np.flatnonzero(
                        (np.abs(placed_xy[: len(placed)] - xy) < (radius + placed_r[: len(placed), None])).all(axis=1)
                    )
                    if any(norm(xy - placed[i][0][:2]) < radius + placed[i][1] for i in near):
                        continue
                if not room.in_footprint(xy[None, :] + radius * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])).all():
                    continue
                q = quat_from_euler(*angles)
                R = quat_to_rot(q)
                if shape == "box":
                    hz = dot(np.abs(R[2]), size)
                elif shape == "cylinder":
                    r, L = size
                    hz = float(abs(R[2, 2]) * L / 2 + r * np.sqrt(max(0.0, 1 - R[2, 2] ** 2)))
                else:
                    hz = radius
                pos = np.array([xy[0], xy[1], hz])
                placed_xy[len(placed)], placed_r[len(placed)] = xy, radius
                placed.append((pos, radius))
                objects.append({"shape": shape, "pos": pos, "quat": q, "size": size})
                break
    room.objects = objects
    return room


_MAX_CHILDREN = 16  # PyBullet silently truncates a shape array to 16 children


def build_room(client: int, room: Room, visual: bool = True) -> list[int]:
    """Create the floor, the walls and the objects in the PyBullet client; returns body ids.

    Static geometry is grouped into compound bodies of at most 16 shapes (PyBullet's limit
    for ``createCollisionShapeArray``, beyond which it silently drops shapes): about ten
    static bodies instead of hundreds keep Bullet's broadphase cheap.  ``visual=False`` gives
    the bodies no visual shapes (collision is the same; building takes about half the time).
    """
    import pybullet as p  # lazy: an optional heavy dependency (the quadrotor extra)

    ids = []
    plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    ids.append(p.createMultiBody(0, plane, -1, [0, 0, 0], physicsClientId=client))
    geom_types = {"box": p.GEOM_BOX, "cylinder": p.GEOM_CYLINDER, "sphere": p.GEOM_SPHERE}
    shapes = [("box", w[3:], w[:3], (0.0, 0.0, 0.0, 1.0), (0.6, 0.6, 0.6, 1)) for w in room.walls]
    shapes += [(o["shape"], o["size"], o["pos"], o["quat"], (0.8, 0.5, 0.2, 1)) for o in room.objects]
    for lo in range(0, len(shapes), _MAX_CHILDREN):
        group = shapes[lo : lo + _MAX_CHILDREN]
        types, he, radii, lengths, pos, orn = [], [], [], [], [], []
        for shape, size, position, quat, _ in group:
            size = np.asarray(size, float)
            types.append(geom_types[shape])
            he.append([float(x) for x in size] if shape == "box" else [0.0, 0.0, 0.0])
            radii.append(float(size[0]) if shape != "box" else 0.0)
            lengths.append(float(size[1]) if shape == "cylinder" else 0.0)
            pos.append([float(x) for x in position])
            orn.append([float(x) for x in quat])
        col = p.createCollisionShapeArray(
            types,
            radii=radii,
            halfExtents=he,
            lengths=lengths,
            collisionFramePositions=pos,
            collisionFrameOrientations=orn,
            physicsClientId=client,
        )
        # (createVisualShapeArray crashes PyBullet 3.2.7 when given rgbaColors: colour the body instead)
        if not visual:
            ids.append(p.createMultiBody(0, col, -1, [0, 0, 0], physicsClientId=client))
            continue
        vis = p.createVisualShapeArray(
            types,
            radii=radii,
            halfExtents=he,
            lengths=lengths,
            visualFramePositions=pos,
            visualFrameOrientations=orn,
            physicsClientId=client,
        )
        ids.append(p.createMultiBody(0, col, vis, [0, 0, 0], physicsClientId=client))
        p.changeVisualShape(ids[-1], -1, rgbaColor=list(group[0][4]), physicsClientId=client)
    return ids
