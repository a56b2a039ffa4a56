"""Procedurally generated mazes with exact thick-wall geometry (the paper's Dubins-3D world).

Units are the paper's pixels: the defaults give a 2750 x 2750 px image holding a maze of
20 x 20 cells of 125 px, with walls 12.5 px thick; a wall is a capsule (a segment with round
caps).  Generators (seeded, both perfect mazes built with Kruskal's algorithm):
``"rectangular"`` and ``"honeycomb"``.  Batched, exact geometry queries:
:meth:`Maze.point_clearance` (signed distance to the nearest wall surface),
:meth:`Maze.paths_hit` (a path touches a wall or leaves the image) and :meth:`Maze.rays`
(distance to the first wall surface or the image border).

The units (docs/original-code.md, item 25), the generators and the queries in detail:
:class:`Maze` and :func:`generate_maze`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rmm_envs.worlds.bounds import MAX_MAGNITUDE, MAX_MAZE_SIDE, within_bounds

__all__ = ["MAZE_GENERATORS", "Maze", "generate_maze", "render_occupancy"]

MAZE_GENERATORS = ("rectangular", "honeycomb")


def _kruskal(n_cells: int, edges: list[tuple[int, int]], rng: np.random.Generator) -> set[int]:
    """Indices of ``edges`` forming a uniformly shuffled Kruskal spanning tree."""
    parent = list(range(n_cells))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    tree = set()
    for k in rng.permutation(len(edges)):
        a, b = edges[k]
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
            tree.add(int(k))
    return tree


def _seg_point_sq(ax, ay, bx, by, px, py):
    """Squared distance from points p to segments a-b (broadcasting arrays)."""
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(dd > 0, ((px - ax) * dx + (py - ay) * dy) / dd, 0.0)
    t = np.clip(t, 0.0, 1.0)
    ex, ey = ax + t * dx - px, ay + t * dy - py
    return ex * ex + ey * ey


def _seg_seg_sq(p0x, p0y, p1x, p1y, q0x, q0y, q1x, q1y):
    """Squared distance between segments p0-p1 and q0-q1 (0 if they cross)."""
    d = np.minimum(
        np.minimum(_seg_point_sq(q0x, q0y, q1x, q1y, p0x, p0y), _seg_point_sq(q0x, q0y, q1x, q1y, p1x, p1y)),
        np.minimum(_seg_point_sq(p0x, p0y, p1x, p1y, q0x, q0y), _seg_point_sq(p0x, p0y, p1x, p1y, q1x, q1y)),
    )

    def orient(ax, ay, bx, by, cx, cy):
        return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)

    o1 = orient(p0x, p0y, p1x, p1y, q0x, q0y)
    o2 = orient(p0x, p0y, p1x, p1y, q1x, q1y)
    o3 = orient(q0x, q0y, q1x, q1y, p0x, p0y)
    o4 = orient(q0x, q0y, q1x, q1y, p1x, p1y)
    cross = (o1 * o2 < 0) & (o3 * o4 < 0)
    return np.where(cross, 0.0, d)


@dataclass
class Maze:
    """Walls ``(W, 4)`` as segments ``(x0, y0, x1, y1)`` in px, with their thickness.

    A wall is the set of points within ``thickness / 2`` of its segment (a capsule).  Queries are
    batched and exact: :meth:`point_clearance` (distance to the nearest wall surface, negative
    inside a wall; points outside the image are invalid), :meth:`paths_hit` (a path ``(N, S, 2+)``
    fails if a point is inside a wall or outside the image, or a segment between points touches
    a wall) and :meth:`rays`.  Per-root candidate walls come from a bucket grid, so a query tests
    only the few walls near it.

    ``cells`` (``(C, 2)`` centres) and ``passages`` (``(P, 2)`` pairs of cells joined by an
    opening) describe the maze's graph for connectivity checks.
    """

    walls: np.ndarray
    width: float = 2750.0
    height: float = 2750.0
    thickness: float = 12.5
    #: the generator that made it ("custom": none); a stored name: its attribute name enters the start
    #: fingerprints stored with results (rmm_envs.starts.start_fingerprint), so it keeps this spelling
    kind: str = "custom"
    cells: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    passages: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=int))
    bucket: float = 50.0
    reach: float = 60.0

    def __post_init__(self) -> None:
        w = np.asarray(self.walls, dtype=float)
        if w.ndim != 2 or w.shape[1] != 4 or not np.all(np.isfinite(w)):
            raise ValueError(f"walls must be finite (W, 4) segments [x0, y0, x1, y1], got shape {w.shape}")
        if not (self.thickness > 0 and self.width > 0 and self.height > 0):
            raise ValueError(
                f"thickness, width and height must be > 0, got {self.thickness}, {self.width}, {self.height}"
            )
        self.walls = w
        self.half = self.thickness / 2.0
        self._build_buckets()

    # ------------------------------------------------------------------ spatial index
    def _build_buckets(self) -> None:
        """For each bucket, the walls within ``reach + half`` of any point of the bucket."""
        b = self.bucket
        self.nbx = int(np.ceil(self.width / b)) + 1
        self.nby = int(np.ceil(self.height / b)) + 1
        cx = (np.arange(self.nbx) + 0.5) * b
        cy = (np.arange(self.nby) + 0.5) * b
        gx, gy = np.meshgrid(cx, cy, indexing="ij")
        centres = np.column_stack([gx.ravel(), gy.ravel()])
        w = self.walls
        radius = self.reach + self.half + b * np.sqrt(0.5)  # covers the whole bucket
        d2 = _seg_point_sq(w[None, :, 0], w[None, :, 1], w[None, :, 2], w[None, :, 3], centres[:, 0:1], centres[:, 1:2])
        near = d2 <= radius * radius
        counts = near.sum(axis=1)
        k = max(1, int(counts.max()) if counts.size else 1)
        table = np.full((centres.shape[0], k), w.shape[0], dtype=np.int64)  # index W = a dummy far wall
        for i in range(centres.shape[0]):
            idx = np.nonzero(near[i])[0]
            table[i, : idx.size] = idx
        self._table = table
        far = np.array([[-1e9, -1e9, -1e9, -1e9]])
        self._walls_ext = np.vstack([w, far])

    def _candidates(self, points: np.ndarray) -> np.ndarray:
        """``(N, K)`` indices (into the extended wall array) of walls near each point."""
        ix = np.clip((points[:, 0] // self.bucket).astype(np.int64), 0, self.nbx - 1)
        iy = np.clip((points[:, 1] // self.bucket).astype(np.int64), 0, self.nby - 1)
        return self._table[ix * self.nby + iy]

    # ------------------------------------------------------------------ queries
    def inside_image(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float)
        return (p[..., 0] >= 0) & (p[..., 0] <= self.width) & (p[..., 1] >= 0) & (p[..., 1] <= self.height)

    def point_clearance(self, points: np.ndarray) -> np.ndarray:
        """Distance from each point ``(N, 2)`` to the nearest wall surface (< 0 inside a wall).

        Exact for walls within ``reach`` of the point; farther walls report ``reach`` at least.
        """
        p = np.asarray(points, dtype=float)[:, :2]
        cand = self._candidates(p)
        w = self._walls_ext[cand]  # (N, K, 4)
        d2 = _seg_point_sq(w[..., 0], w[..., 1], w[..., 2], w[..., 3], p[:, 0:1], p[:, 1:2])
        return np.sqrt(d2.min(axis=1)) - self.half

    def state_failed(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=float)[:, :2]
        return ~self.inside_image(p) | (self.point_clearance(p) <= 0)

    def paths_hit(self, paths: np.ndarray, reach_from: np.ndarray | None = None) -> np.ndarray:
        """``(N,)`` bool: any point or segment of each path ``(N, S, 2+)`` fails.

        Candidate walls are those near ``reach_from`` (``(N, 2)``, default the path's first
        point); every point of the path must lie within ``reach`` of it (the estimator's
        trees do: 2 levels of 20 px).
        """
        xy = np.asarray(paths, dtype=float)[..., :2]
        n, s = xy.shape[:2]
        origin = xy[:, 0] if reach_from is None else np.asarray(reach_from, dtype=float)
        out = ~self.inside_image(xy).all(axis=1)
        cand = self._candidates(origin)  # (N, K)
        w = self._walls_ext[cand]  # (N, K, 4)
        wx0, wy0, wx1, wy1 = (w[:, None, :, i] for i in range(4))  # (N, 1, K)
        px, py = xy[:, :, 0:1], xy[:, :, 1:2]  # (N, S, 1)
        d2 = _seg_point_sq(wx0, wy0, wx1, wy1, px, py)  # (N, S, K)
        h2 = self.half * self.half
        out |= (d2 <= h2).any(axis=(1, 2))
        if s >= 2:
            # a segment can only touch a wall if an endpoint is within half + its length of it
            seg_len = np.sqrt(((xy[:, 1:] - xy[:, :-1]) ** 2).sum(-1))  # (N, S-1)
            lim = (self.half + seg_len)[..., None] ** 2
            amb = (np.minimum(d2[:, :-1], d2[:, 1:]) <= lim) & ~out[:, None, None]
            if amb.any():
                i, j, k = np.nonzero(amb)
                q = w[i, k]
                dd = _seg_seg_sq(
                    xy[i, j, 0], xy[i, j, 1], xy[i, j + 1, 0], xy[i, j + 1, 1], q[:, 0], q[:, 1], q[:, 2], q[:, 3]
                )
                hit = dd <= h2
                out[i[hit]] = True
        return out

    def rays(self, states: np.ndarray, n_rays: int = 8) -> np.ndarray:
        """Distances ``(N, n_rays)`` along rays at ``heading + 2 pi k / n_rays`` to the first wall
        surface or the image border (0 from inside a wall or outside the image)."""
        st = np.asarray(states, dtype=float)
        ox, oy = st[:, 0:1], st[:, 1:2]
        ang = st[:, 2:3] + 2.0 * np.pi * np.arange(n_rays)[None, :] / n_rays
        dx, dy = np.cos(ang), np.sin(ang)  # (N, R)
        # border: the image rectangle
        with np.errstate(divide="ignore", invalid="ignore"):
            tx = np.where(dx > 0, (self.width - ox) / dx, np.where(dx < 0, -ox / dx, np.inf))
            ty = np.where(dy > 0, (self.height - oy) / dy, np.where(dy < 0, -oy / dy, np.inf))
        best = np.minimum(tx, ty)
        w = self.walls
        # all walls (rays have no range limit); chunked to bound memory
        for lo in range(0, w.shape[0], 256):
            ww = w[lo : lo + 256]
            t = _ray_capsule(
                ox[..., None],
                oy[..., None],
                dx[..., None],
                dy[..., None],
                ww[:, 0],
                ww[:, 1],
                ww[:, 2],
                ww[:, 3],
                self.half,
            )  # (N, R, K)
            best = np.minimum(best, t.min(axis=2))
        dead = self.state_failed(st[:, :2])
        return np.where(dead[:, None], 0.0, np.maximum(best, 0.0))


def _ray_capsule(ox, oy, dx, dy, ax, ay, bx, by, r):
    """Smallest ``t >= 0`` where ``o + t d`` touches the capsule ``a-b`` of radius ``r`` (inf if none)."""
    ex, ey = bx - ax, by - ay
    L = np.sqrt(ex * ex + ey * ey)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux, uy = np.where(L > 0, ex / L, 1.0), np.where(L > 0, ey / L, 0.0)
    nx, ny = -uy, ux
    best = np.full(np.broadcast(ox, ax).shape, np.inf)
    # the two long sides: lines offset by +-r along the normal, limited to the segment's span
    dn = dx * nx + dy * ny
    for sgn in (1.0, -1.0):
        cx, cy = ax + sgn * r * nx, ay + sgn * r * ny
        with np.errstate(divide="ignore", invalid="ignore"):  # a ray parallel to the side: t is inf or nan
            t = ((cx - ox) * nx + (cy - oy) * ny) / dn
            hx, hy = ox + t * dx - cx, oy + t * dy - cy
            along = hx * ux + hy * uy
        ok = (t >= 0) & (along >= 0) & (along <= L) & np.isfinite(t)
        best = np.where(ok, np.minimum(best, t), best)
    # the two round caps
    for px, py in ((ax, ay), (bx, by)):
        fx, fy = ox - px, oy - py
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - r * r
        disc = b * b - c
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        ok = (disc >= 0) & (t >= 0)
        best = np.where(ok, np.minimum(best, t), best)
    return best


def _rect_maze(rng, rows, cols, cell, margin):
    cells, edges, shared = [], [], []
    idx = lambda r, c: r * cols + c  # noqa: E731
    for r in range(rows):
        for c in range(cols):
            cells.append((margin + (c + 0.5) * cell, margin + (r + 0.5) * cell))
    for r in range(rows):
        for c in range(cols):
            x0, y0 = margin + c * cell, margin + r * cell
            if c + 1 < cols:
                edges.append((idx(r, c), idx(r, c + 1)))
                shared.append((x0 + cell, y0, x0 + cell, y0 + cell))
            if r + 1 < rows:
                edges.append((idx(r, c), idx(r + 1, c)))
                shared.append((x0, y0 + cell, x0 + cell, y0 + cell))
    tree = _kruskal(rows * cols, edges, rng)
    walls = [shared[k] for k in range(len(edges)) if k not in tree]
    W, H = margin + cols * cell, margin + rows * cell
    walls += [(margin, margin, W, margin), (W, margin, W, H), (W, H, margin, H), (margin, H, margin, margin)]
    return np.array(walls), np.array(cells), np.array([edges[k] for k in sorted(tree)])


def _hex_maze(
    rng: np.random.Generator, rows: int, cols: int, cell: float, margin: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pointy-top hexagons of circumradius R in offset rows (odd rows shifted right)."""
    R = cell / np.sqrt(3.0)  # width of a hexagon = cell
    centres = {}
    for r in range(rows):
        for c in range(cols):
            x = margin + cell * (c + 0.5 + 0.5 * (r % 2))
            y = margin + R + r * 1.5 * R
            centres[(r, c)] = (x, y)
    keys = list(centres)
    index = {k: i for i, k in enumerate(keys)}

    def corners(x, y):
        return [
            (x + R * np.cos(np.pi / 6 + k * np.pi / 3), y + R * np.sin(np.pi / 6 + k * np.pi / 3)) for k in range(6)
        ]

    def edge_key(p, q):
        a = (round(p[0], 6), round(p[1], 6))
        b = (round(q[0], 6), round(q[1], 6))
        return (a, b) if a <= b else (b, a)

    owner: dict = {}
    for k, (x, y) in centres.items():
        cs = corners(x, y)
        for j in range(6):
            owner.setdefault(edge_key(cs[j], cs[(j + 1) % 6]), []).append(index[k])
    edges, shared, walls = [], [], []
    for ek, cells_of in owner.items():
        seg = (*ek[0], *ek[1])
        if len(cells_of) == 2:
            edges.append(tuple(cells_of))
            shared.append(seg)
        else:
            walls.append(seg)  # boundary
    tree = _kruskal(len(keys), edges, rng)
    walls += [shared[k] for k in range(len(edges)) if k not in tree]
    return np.array(walls), np.array([centres[k] for k in keys]), np.array([edges[k] for k in sorted(tree)])


def generate_maze(
    rng: np.random.Generator,
    generator: str = "rectangular",
    rows: int = 20,
    cols: int = 20,
    cell: float = 125.0,
    thickness: float = 12.5,
) -> Maze:
    """A seeded perfect maze made by ``generator`` with a one-cell margin around it (pixel units).

    Both generators make perfect mazes (every cell reachable from every other by exactly one path), a
    random spanning tree built with Kruskal's algorithm: ``"rectangular"`` a rows x cols grid of
    square cells, ``"honeycomb"`` pointy-top hexagons in offset rows.  The defaults are the
    paper's: 20 x 20 cells of 125 px, walls 12.5 px thick (mazegen's 3-unit round-capped stroke
    at 300 dpi), a 2750 x 2750 px image."""
    if generator not in MAZE_GENERATORS:
        raise ValueError(f"unknown maze generator {generator!r}; expected one of {MAZE_GENERATORS}")
    sides_ok = all(
        isinstance(x, (int, float, np.integer, np.floating))
        and not isinstance(x, bool)
        and within_bounds(x)
        and int(x) == x
        for x in (rows, cols)
    )
    if not sides_ok or not (2 <= rows <= MAX_MAZE_SIDE and 2 <= cols <= MAX_MAZE_SIDE):  # checked before any allocation
        raise ValueError(
            f"rows and cols must be integers in [2, {MAX_MAZE_SIDE}], got {str(rows)[:40]}, {str(cols)[:40]}"
        )
    if not (within_bounds([cell, thickness]) and cell > thickness > 0):
        raise ValueError(
            f"need finite cell > thickness > 0 of at most {MAX_MAGNITUDE:g}, got cell={str(cell)[:40]}, "
            f"thickness={str(thickness)[:40]}"
        )
    rows, cols = int(rows), int(cols)
    margin = cell
    if generator == "rectangular":
        walls, cells, passages = _rect_maze(rng, rows, cols, cell, margin)
        width, height = 2 * margin + cols * cell, 2 * margin + rows * cell
    else:
        walls, cells, passages = _hex_maze(rng, rows, cols, cell, margin)
        width = 2 * margin + (cols + 0.5) * cell
        height = 2 * margin + (1.5 * (rows - 1) + 2) * cell / np.sqrt(3.0)
    return Maze(
        walls,
        width=float(width),
        height=float(height),
        thickness=thickness,
        kind=generator,
        cells=cells,
        passages=passages,
    )


def render_occupancy(maze: Maze, resolution: float = 1.0) -> np.ndarray:
    """A boolean occupancy image (True = wall or outside), rows = y, at ``resolution`` px per pixel."""
    nx, ny = int(np.ceil(maze.width / resolution)), int(np.ceil(maze.height / resolution))
    xs = (np.arange(nx) + 0.5) * resolution
    out = np.zeros((ny, nx), dtype=bool)
    for j in range(ny):
        pts = np.column_stack([xs, np.full(nx, (j + 0.5) * resolution)])
        out[j] = maze.point_clearance(pts) <= 0
    return out
