"""A Dubins4D vehicle on a map of your own: :class:`Dubins4DMapScene`.

:class:`rmm_envs.systems.dubins4d.scene.Dubins4DScene` (dynamics, observation, leaf heuristic) with
the world's questions (inside, path contact, rays) answered by a
:class:`rmm_envs.systems.dubins4d_map.pymunk_world.PymunkWorld` instead of the analytic circles.
"""

from __future__ import annotations

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.dubins4d.scene import Dubins4DScene
from rmm_envs.systems.dubins4d_map.pymunk_world import PymunkWorld
from rmm_envs.systems.dubins4d_map.shape_map import ShapeMap

__all__ = ["Dubins4DMapScene"]


class Dubins4DMapScene(Dubins4DScene):
    """The :class:`rmm_envs.risk.RiskScene` of ``Dubins4DMapGuarded-v0``: ``world`` is the map's
    :class:`PymunkWorld` (built once per map and shared by the episodes on it), ``goal`` the
    episode's goal disc ``(3,)``.  The env uses this very object for its own observations and
    collision checks, so labels and the env agree by construction."""

    # every member of Dubins4DScene that reads a CircleWorld is overridden below to ask the PymunkWorld
    world: PymunkWorld  # type: ignore[assignment]  # replaces the base's CircleWorld, see the comment above

    def __init__(
        self,
        world: PymunkWorld,
        goal: np.ndarray,
        dynamics: Dubins4D | None = None,
        n_rays: int = 12,
        ray_length: float = 10.0,
    ) -> None:
        self.dynamics = dynamics or Dubins4D()
        self.world = world
        self._goal = np.asarray(goal, dtype=float).reshape(3)
        self.n_rays = int(n_rays)
        self.ray_length = float(ray_length)
        self.obs_dim = 5 + self.n_rays

    @property
    def map(self) -> ShapeMap:
        return self.world.map

    @property
    def obstacles(self) -> np.ndarray:
        """The map's circles ``(K, 3)`` (its only obstacles when :attr:`ShapeMap.circles_only`)."""
        return self.world.map.circles

    @property
    def goal(self) -> np.ndarray:
        return self._goal

    def state_failed(self, states: np.ndarray) -> np.ndarray:
        return self.world.points_inside(np.asarray(states)[:, :2])

    def path_failed(self, paths: np.ndarray) -> np.ndarray:
        """``(N,)`` bool: a path ``(N, S, 4)`` touches an obstacle at a point or segment."""
        return self.world.paths_hit(paths)

    def rays(self, states: np.ndarray, n_rays: int) -> np.ndarray:
        return self.world.rays(states[:, :2], states[:, 2], n_rays, self.ray_length)
