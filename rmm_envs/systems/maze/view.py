"""The maze car seen from above: its spec's ``view``."""

from __future__ import annotations

import numpy as np

from rmm_envs.views.base import WALL, Window
from rmm_envs.views.planar import CarView, PlanarWorld

__all__ = ["MazeView", "maze_view"]


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


def maze_view(env, size: int) -> MazeView:
    """The ``Dubins3DMaze`` system's view (its spec's ``view``)."""
    return MazeView(size)
