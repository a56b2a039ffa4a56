"""What every view shares: the colours, the world-to-pixel window and the :class:`View` protocol.

A view draws one system's pictures with Pillow's ``ImageDraw``.  It never reads an env's private
attributes: :meth:`View.world` reads the episode's fixed geometry through ``privileged()`` (or
another public accessor) once per episode, :meth:`View.state` the true state after every step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from PIL import Image, ImageDraw

__all__ = [
    "BACKGROUND",
    "BODY_OUTLINE",
    "COLLISION",
    "DRIVER",
    "GOAL",
    "GUARDIAN",
    "OBSTACLE",
    "WALL",
    "View",
    "Window",
    "convex_hull",
]

BACKGROUND = (255, 255, 255)
#: the path and the body while the driver controls / while the guardian controls
DRIVER = (31, 119, 180)
GUARDIAN = (255, 127, 14)
GOAL = (44, 160, 44)
OBSTACLE = (214, 39, 40)
WALL = (40, 40, 40)
COLLISION = (148, 0, 211)
BODY_OUTLINE = (0, 0, 0)
LIGHT = (225, 225, 225)


@dataclass(frozen=True)
class Window:
    """The world rectangle ``[x0, x1] x [y0, y1]`` (y up) shown on ``width x height`` pixels
    whose top-left corner is at ``(left, top)`` of the picture.

    Pillow fills the pixels from ``floor`` of a shape's low coordinate to ``floor`` of its high
    one, both included: a shape comes out up to half a pixel fatter than the set of pixel
    centres ``x0 + (i + 1/2) / scale`` it holds (what the envs' own frames fill,
    :class:`rmm_envs.envs._render.Canvas`).  :meth:`disc` and :meth:`capsule` take that half
    pixel off; polygons keep it."""

    x0: float
    x1: float
    y0: float
    y1: float
    width: int
    height: int
    left: int = 0
    top: int = 0

    @classmethod
    def square(cls, cx: float, cy: float, half: float, size: int, left: int = 0) -> Window:
        return cls(cx - half, cx + half, cy - half, cy + half, size, size, left)

    @property
    def scale(self) -> float:
        """Pixels per world unit along x."""
        return self.width / (self.x1 - self.x0)

    def px(self, x, y) -> tuple[float, float]:
        """The pixel of world point ``(x, y)``."""
        return (
            self.left + (float(x) - self.x0) * self.width / (self.x1 - self.x0),
            self.top + (self.y1 - float(y)) * self.height / (self.y1 - self.y0),
        )

    def pixels(self, xy: ArrayLike) -> np.ndarray:
        """Pixels ``(N, 2)`` of world points ``(N, 2)``."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        out = np.empty_like(xy)
        out[:, 0] = self.left + (xy[:, 0] - self.x0) * (self.width / (self.x1 - self.x0))
        out[:, 1] = self.top + (self.y1 - xy[:, 1]) * (self.height / (self.y1 - self.y0))
        return out

    def disc(self, draw: ImageDraw.ImageDraw, x, y, r, fill=None, outline=None, width: int = 1) -> None:
        """A circle of world radius ``r`` (at least one pixel)."""
        cx, cy = self.px(x, y)
        # half a pixel less: Pillow fills the box's pixels inclusively (see the class)
        rx = max(float(r) * self.scale, 1.0) - 0.5
        ry = max(float(r) * self.height / (self.y1 - self.y0), 1.0) - 0.5
        draw.ellipse((cx - rx, cy - ry, cx + rx, cy + ry), fill=fill, outline=outline, width=width)

    def polygon(self, draw: ImageDraw.ImageDraw, vertices, fill=None, outline=None, width: int = 1) -> None:
        pts = [tuple(p) for p in self.pixels(vertices).tolist()]
        if len(pts) >= 3:
            draw.polygon(pts, fill=fill, outline=outline, width=width)

    def capsule(self, draw: ImageDraw.ImageDraw, a, b, r, fill) -> None:
        """Every point within world distance ``r`` of the segment ``a-b`` (a wall): its rectangle
        as a polygon and its round caps as discs (at least one pixel wide).  Not a wide
        ``draw.line``: Pillow rounds a line's width to whole pixels and shifts an even width by
        half a pixel, left for a vertical line and down for a horizontal one."""
        r = float(r)
        h = max(r - 0.5 / self.scale, 0.5 / self.scale)  # half a pixel less (see the class); disc does the same
        (ax, ay), (bx, by) = (float(a[0]), float(a[1])), (float(b[0]), float(b[1]))
        length = float(np.hypot(bx - ax, by - ay))
        if length > 0:
            nx, ny = -(by - ay) / length * h, (bx - ax) / length * h
            self.polygon(
                draw, [(ax + nx, ay + ny), (bx + nx, by + ny), (bx - nx, by - ny), (ax - nx, ay - ny)], fill=fill
            )
        for x, y in ((ax, ay), (bx, by)):
            self.disc(draw, x, y, r, fill=fill)

    def rectangle(self, draw: ImageDraw.ImageDraw, lo, hi, fill=None, outline=None, width: int = 1) -> None:
        (ax, ay), (bx, by) = self.px(lo[0], hi[1]), self.px(hi[0], lo[1])
        draw.rectangle((ax, ay, max(ax, bx), max(ay, by)), fill=fill, outline=outline, width=width)


def convex_hull(points: np.ndarray) -> np.ndarray:
    """The convex hull ``(H, 2)`` of 2-D points (Andrew's monotone chain), counter-clockwise."""
    pts = sorted({(float(x), float(y)) for x, y in np.asarray(points, float).reshape(-1, 2)})
    if len(pts) <= 2:
        return np.array(pts)

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list = []
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


class View:
    """One system's picture: the protocol :class:`rmm_envs.views.EpisodeRecorder` draws through.

    ``width x height``: the picture's size in pixels (the strip goes below it).  A view may
    show the state in several panels (the quadrotor's top and side views): :meth:`path_pixels`
    gives one pixel pair per panel.

    * :meth:`world` reads what does not move in this episode (called once, after ``reset``);
    * :meth:`draw_static` draws it (called **once per episode**; the recorder reuses the image);
    * :meth:`state` reads the true state after a step (public accessors only);
    * :meth:`path_pixels` maps states to the path's pixels, ``(N, panels, 2)``;
    * :meth:`draw_body` draws the moving body at one state over the static layer and the path.
    """

    width: int = 512
    height: int = 512
    #: ``True``: :meth:`capture` returns a picture per step that the frame shows (the env's own frame)
    captures: bool = False

    def world(self, env) -> Any:
        """The episode's fixed geometry (obstacles, walls, goal...), read once after ``reset``."""
        return None

    def draw_static(self, draw: ImageDraw.ImageDraw, world: Any) -> None:
        """Draw what does not move (on a white picture of ``width x height``)."""

    def state(self, env) -> np.ndarray:
        """The true state after a step: ``env.unwrapped.true_state`` by default."""
        return np.asarray(env.unwrapped.true_state, dtype=float).copy()

    def path_pixels(self, states: np.ndarray) -> np.ndarray:
        """Pixels ``(N, panels, 2)`` of the path through ``states`` ``(N, D)``; ``panels`` may be 0."""
        return np.zeros((np.asarray(states).shape[0], 0, 2))

    def draw_body(self, draw: ImageDraw.ImageDraw, state: np.ndarray, active: bool, world: Any) -> None:
        """Draw the moving body at ``state`` (colour by ``active``: who controls the interval that ended there)."""

    def capture(self, env) -> np.ndarray | None:
        """A picture to keep for this step (views with :attr:`captures`); ``None`` otherwise."""
        return None

    def paste(self, picture: Image.Image, frame: np.ndarray, active: bool) -> None:
        """Put a captured picture (:meth:`capture`) on the frame's ``picture`` (views with :attr:`captures`)."""

    def new_picture(self) -> Image.Image:
        return Image.new("RGB", (self.width, self.height), BACKGROUND)
