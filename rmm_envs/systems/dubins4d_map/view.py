"""The Dubins4D car on a map of your own seen from above: its spec's ``view``."""

from __future__ import annotations

import numpy as np

from rmm_envs.systems.dubins4d_map.shape_map import load_map
from rmm_envs.views.base import Window
from rmm_envs.views.planar import CarView, PlanarWorld

__all__ = ["MapView", "map_view"]


class MapView(CarView):
    """``Dubins4DMapGuarded-v0`` / ``...Parallel-v0``: the square around the map and its start box
    (5% margin), circles, polygons and walls red, the start box outlined, the goal green."""

    def world(self, env) -> PlanarWorld:
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


def map_view(env, size: int) -> MapView:
    """The ``Dubins4DMap`` system's view (its spec's ``view``)."""
    return MapView(size)
