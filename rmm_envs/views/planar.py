"""What every top-down view of a planar car shares: :class:`PlanarWorld` and :class:`CarView` (each
system's own view subclasses it in the system's folder, ``rmm_envs/systems/<system>/view.py``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from PIL import ImageDraw

from rmm_envs.views.base import BODY_OUTLINE, DRIVER, GOAL, GUARDIAN, LIGHT, OBSTACLE, View, Window

__all__ = ["CarView", "PlanarWorld"]


@dataclass
class PlanarWorld:
    """What a planar view draws once: circles ``(K, 3)``, polygons, capsules ``(a, b, r)``, the goal
    ``[x, y, r]`` (or ``None``) and outlined boxes ``(lo, hi)``."""

    circles: np.ndarray
    goal: np.ndarray | None
    polygons: list
    capsules: list
    outlines: list


class CarView(View):
    """A car seen from above: state ``(x, y, heading, ...)``; the body a disc of ``body_radius``
    with a heading tick.  Subclasses set :attr:`window` (in :meth:`world`) and read the world."""

    body_radius: float = 0.4
    obstacle_colour = OBSTACLE

    def __init__(self, size: int = 512) -> None:
        self.width = self.height = int(size)
        self.window = Window.square(0.0, 0.0, 15.0, self.width)

    def draw_static(self, draw: ImageDraw.ImageDraw, world: PlanarWorld) -> None:
        w = self.window
        for lo, hi in world.outlines:
            w.rectangle(draw, lo, hi, outline=LIGHT, width=2)
        if world.goal is not None:  # under the obstacles, as the env's own frame: a goal may overlap one
            gx, gy, gr = (float(v) for v in world.goal[:3])
            w.disc(draw, gx, gy, gr, fill=GOAL)
            w.disc(draw, gx, gy, gr + 4.0 / w.scale, outline=GOAL, width=2)
        for x, y, r in np.asarray(world.circles, float).reshape(-1, 3):
            w.disc(draw, x, y, r, fill=self.obstacle_colour)
        for poly in world.polygons:
            w.polygon(draw, poly, fill=self.obstacle_colour)
        for a, b, r in world.capsules:
            w.capsule(draw, a, b, r, self.obstacle_colour)

    def path_pixels(self, states: np.ndarray) -> np.ndarray:
        st = np.asarray(states, dtype=float).reshape(-1, np.asarray(states).shape[-1])
        return self.window.pixels(st[:, :2])[:, None, :]

    def draw_body(self, draw: ImageDraw.ImageDraw, state: np.ndarray, active: bool, world: Any) -> None:
        w = self.window
        x, y, th = float(state[0]), float(state[1]), float(state[2])
        colour = GUARDIAN if active else DRIVER
        r = max(self.body_radius, 5.0 / w.scale)  # at least 5 px, so that a small car shows
        w.disc(draw, x, y, r, fill=colour, outline=BODY_OUTLINE, width=1)
        tip = w.px(x + 2.2 * r * np.cos(th), y + 2.2 * r * np.sin(th))
        draw.line([w.px(x, y), tip], fill=BODY_OUTLINE, width=3)
