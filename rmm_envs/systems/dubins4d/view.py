"""The Dubins4D car among circles seen from above: its spec's ``view``."""

from __future__ import annotations

import numpy as np

from rmm_envs.systems.dubins4d.starts import HALF
from rmm_envs.views.planar import CarView, PlanarWorld

__all__ = ["Dubins4DView", "dubins4d_view"]


class Dubins4DView(CarView):
    """``Dubins4DGuarded-v0`` / ``Dubins4DParallel-v0``: the window ``[-15, 15]^2`` m (the env's
    own frame), the generation arena outlined, obstacles red, the goal green."""

    def world(self, env) -> PlanarWorld:
        priv = env.unwrapped.privileged()
        return PlanarWorld(
            circles=np.asarray(priv["obstacles"], float).reshape(-1, 3),
            goal=np.asarray(priv["goal"], float),
            polygons=[],
            capsules=[],
            outlines=[((-HALF, -HALF), (HALF, HALF))],
        )


def dubins4d_view(env, size: int) -> Dubins4DView:
    """The ``Dubins4D`` system's view (its spec's ``view``)."""
    return Dubins4DView(size)
