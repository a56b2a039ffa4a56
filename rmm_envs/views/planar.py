"""Top-down views of the planar cars: Dubins4D among circles, Dubins4D on a map, the maze car."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from PIL import ImageDraw

from rmm_envs.views.base import BODY_OUTLINE, DRIVER, GOAL, GUARDIAN, LIGHT, OBSTACLE, WALL, View, Window

__all__ = ["CarView", "Dubins4DView", "MapView", "MazeView", "dubins4d_view", "map_view", "maze_view"]


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


class Dubins4DView(CarView):
    """``Dubins4DGuarded-v0`` / ``Dubins4DParallel-v0``: the window ``[-15, 15]^2`` m (the env's
    own frame), the generation arena outlined, obstacles red, the goal green."""

    def world(self, env) -> PlanarWorld:
        from rmm_envs.envs.dubins4d_start import HALF

        priv = env.unwrapped.privileged()
        return PlanarWorld(
            circles=np.asarray(priv["obstacles"], float).reshape(-1, 3),
            goal=np.asarray(priv["goal"], float),
            polygons=[],
            capsules=[],
            outlines=[((-HALF, -HALF), (HALF, HALF))],
        )


class MapView(CarView):
    """``Dubins4DMapGuarded-v0`` / ``...Parallel-v0``: the square around the map and its start box
    (5% margin), circles, polygons and walls red, the start box outlined, the goal green."""

    def world(self, env) -> PlanarWorld:
        from rmm_envs.worlds.shape_map import load_map

        priv = env.unwrapped.privileged()
        m = load_map(priv["map"])
        start = np.asarray(m.start_box, float)
        box = np.vstack([m.bounding_box(), start])
        lo, hi = box.min(axis=0), box.max(axis=0)
        c, half = (lo + hi) / 2, 0.525 * float(np.max(hi - lo))
        self.window = Window.square(float(c[0]), float(c[1]), half, self.width)
        return PlanarWorld(
            circles=np.asarray(m.circles, float).reshape(-1, 3),
            goal=np.asarray(priv["goal"], float),
            polygons=[np.asarray(p, float) for p in m.polygons],
            capsules=[(a, b, t / 2) for a, b, t in m.segments],
            outlines=[(start[0], start[1])],
        )


class MazeView(CarView):
    """``Dubins3DMazeGuarded-v0`` / ``...Parallel-v0``: the maze's walls (capsules, dark), the goal
    green; lengths in pixels of the maze's image (the car is drawn at 25 px)."""

    body_radius = 25.0
    obstacle_colour = WALL

    def world(self, env) -> PlanarWorld:
        priv = env.unwrapped.privileged()
        m = priv["maze"]
        side = float(max(m.width, m.height))
        self.window = Window(0.0, side, 0.0, side, self.width, self.height)
        half = float(m.half)
        return PlanarWorld(
            circles=np.zeros((0, 3)),
            goal=np.asarray(priv["goal"], float),
            polygons=[],
            capsules=[((w[0], w[1]), (w[2], w[3]), half) for w in np.asarray(m.walls, float)],
            outlines=[],
        )


def dubins4d_view(env, size: int) -> Dubins4DView:
    """The ``Dubins4D`` system's view (its spec's ``view``)."""
    return Dubins4DView(size)


def map_view(env, size: int) -> MapView:
    """The ``Dubins4DMap`` system's view (its spec's ``view``)."""
    return MapView(size)


def maze_view(env, size: int) -> MazeView:
    """The ``Dubins3DMaze`` system's view (its spec's ``view``)."""
    return MazeView(size)
