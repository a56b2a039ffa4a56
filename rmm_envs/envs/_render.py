"""A tiny numpy rasteriser for top-down 2D frames (no display, no extra dependency)."""

from __future__ import annotations

import numpy as np

from rmm_envs.systems.dubins4d.circles import ray_cast

WHITE = (255, 255, 255)
RED = (214, 39, 40)
GREEN = (44, 160, 44)
BLUE = (31, 119, 180)
GREY = (170, 170, 170)
ORANGE = (255, 127, 14)


class Canvas:
    """An RGB image over the world window ``[x0, x1] x [y0, y1]`` (y up)."""

    def __init__(self, size: int, x0: float, x1: float, y0: float, y1: float) -> None:
        self.size = size
        self.img = np.full((size, size, 3), 255, dtype=np.uint8)
        self.x0, self.y0 = x0, y0
        self.sx = size / (x1 - x0)
        self.sy = size / (y1 - y0)
        c = np.arange(size) + 0.5
        self.wx = x0 + c / self.sx  # world x of each column
        self.wy = y1 - c / self.sy  # world y of each row (row 0 is the top)

    def disc(self, x: float, y: float, r: float, colour) -> None:
        mask = (self.wx[None, :] - x) ** 2 + (self.wy[:, None] - y) ** 2 <= r * r
        self.img[mask] = colour

    def ring(self, x: float, y: float, r: float, colour, width: float) -> None:
        d = np.sqrt((self.wx[None, :] - x) ** 2 + (self.wy[:, None] - y) ** 2)
        self.img[np.abs(d - r) <= width / 2] = colour

    def polygon(self, vertices, colour) -> None:
        """Fill a simple polygon ``(V, 2)`` (even-odd rule over the pixel centres)."""
        v = np.asarray(vertices, dtype=float)
        X, Y = self.wx[None, :], self.wy[:, None]
        inside = np.zeros((self.size, self.size), dtype=bool)
        for (xa, ya), (xb, yb) in zip(v, np.roll(v, -1, axis=0), strict=True):
            if ya == yb:
                continue
            crosses = (ya > Y) != (yb > Y)
            x_at = xa + (Y - ya) * (xb - xa) / (yb - ya)
            inside ^= crosses & (X < x_at)
        self.img[inside] = colour

    def capsule(self, x0: float, y0: float, x1: float, y1: float, r: float, colour) -> None:
        """Fill every pixel within ``r`` of the segment ``(x0, y0)-(x1, y1)``."""
        dx, dy = x1 - x0, y1 - y0
        fx, fy = self.wx[None, :] - x0, self.wy[:, None] - y0
        s = np.clip((fx * dx + fy * dy) / max(dx * dx + dy * dy, 1e-300), 0.0, 1.0)
        self.img[(fx - s * dx) ** 2 + (fy - s * dy) ** 2 <= r * r] = colour

    def line(self, x0: float, y0: float, x1: float, y1: float, colour) -> None:
        n = int(max(abs(x1 - x0) * self.sx, abs(y1 - y0) * self.sy)) + 2
        xs = np.linspace(x0, x1, n)
        ys = np.linspace(y0, y1, n)
        cols = ((xs - self.x0) * self.sx).astype(int)
        rows = ((self.wy[0] - ys) * self.sy + 0.5).astype(int)
        ok = (cols >= 0) & (cols < self.size) & (rows >= 0) & (rows < self.size)
        self.img[rows[ok], cols[ok]] = colour


def dubins4d_frame(scene, state, guardian_active: bool, half: float, size: int = 512) -> np.ndarray:
    """Dubins4D's top-down frame of the window ``[-15, 15]^2`` m: the generation arena
    ``[-half, half]^2`` outlined, obstacles red, the goal green with a ring, the rays grey and the
    vehicle blue (driver) or orange (``guardian_active``)."""
    cv = Canvas(size, -15, 15, -15, 15)
    for a, b in (
        ((-half, -half), (half, -half)),
        ((half, -half), (half, half)),
        ((half, half), (-half, half)),
        ((-half, half), (-half, -half)),
    ):
        cv.line(a[0], a[1], b[0], b[1], (225, 225, 225))  # the arena used for generation
    g = scene.goal
    cv.disc(g[0], g[1], g[2], GREEN)
    cv.ring(g[0], g[1], g[2] + 0.25, GREEN, 0.12)
    for ox, oy, r in scene.obstacles:
        cv.disc(ox, oy, r, RED)
    x, y, th, v = state
    rays = ray_cast(state[None, :2], np.array([th]), scene.obstacles, scene.n_rays, scene.ray_length)[0]
    for i, d in enumerate(rays):
        a = th + 2 * np.pi * i / scene.n_rays
        cv.line(x, y, x + d * np.cos(a), y + d * np.sin(a), GREY)
    colour = ORANGE if guardian_active else BLUE
    cv.disc(x, y, 0.4, colour)
    cv.line(x, y, x + (0.5 + v) * np.cos(th), y + (0.5 + v) * np.sin(th), colour)
    return cv.img


def map_frame(scene, state, guardian_active: bool, start_box, size: int = 512) -> np.ndarray:
    """A map's top-down frame: the square window around the map and its start box (5% margin),
    the start box outlined, obstacles red, the goal green with a ring, the rays grey and the
    vehicle blue (driver) or orange (``guardian_active``)."""
    m = scene.map
    box = np.vstack([m.bounding_box(), np.asarray(start_box, float)])
    lo, hi = box.min(axis=0), box.max(axis=0)
    c, half = (lo + hi) / 2, 0.525 * float(np.max(hi - lo))
    cv = Canvas(size, c[0] - half, c[0] + half, c[1] - half, c[1] + half)
    (bx0, by0), (bx1, by1) = start_box
    for a, b in (
        ((bx0, by0), (bx1, by0)),
        ((bx1, by0), (bx1, by1)),
        ((bx1, by1), (bx0, by1)),
        ((bx0, by1), (bx0, by0)),
    ):
        cv.line(a[0], a[1], b[0], b[1], (225, 225, 225))
    g = scene.goal
    cv.disc(g[0], g[1], g[2], GREEN)
    cv.ring(g[0], g[1], g[2] + 0.25, GREEN, 0.12)
    for ox, oy, r in m.circles:
        cv.disc(ox, oy, r, RED)
    for poly in m.polygons:
        cv.polygon(poly, RED)
    for a, b, t in m.segments:
        cv.capsule(a[0], a[1], b[0], b[1], t / 2, RED)
    x, y, th, v = state
    rays = scene.rays(np.asarray(state, float)[None, :], scene.n_rays)[0]
    for i, d in enumerate(rays):
        a = th + 2 * np.pi * i / scene.n_rays
        cv.line(x, y, x + d * np.cos(a), y + d * np.sin(a), GREY)
    colour = ORANGE if guardian_active else BLUE
    cv.disc(x, y, 0.4, colour)
    cv.line(x, y, x + (0.5 + v) * np.cos(th), y + (0.5 + v) * np.sin(th), colour)
    return cv.img
