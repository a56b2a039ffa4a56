"""A Dubins3D car in one maze: :class:`MazeScene`."""

from __future__ import annotations

import numpy as np

from rmm_envs.dynamics.dubins3d import Dubins3D
from rmm_envs.scenes.base import SceneBase
from rmm_envs.worlds.mazes import Maze

__all__ = ["MazeScene"]


class MazeScene(SceneBase):
    """A Dubins3D car in one maze: the :class:`rmm_envs.risk.RiskScene` of ``Dubins3DMaze-v0``.

    A state fails inside a wall or outside the image; a path fails when a point or a segment
    between points touches a wall (exactly).  :meth:`observe` is the env's observation: the
    ``n_rays`` ray lengths.
    """

    state_dim = 3
    dynamics: Dubins3D

    def __init__(self, maze: Maze, dynamics: Dubins3D | None = None, n_rays: int = 8) -> None:
        self.maze = maze
        self.dynamics = dynamics or Dubins3D()
        self.n_rays = n_rays
        self.obs_dim = n_rays

    def state_failed(self, states):
        return self.maze.state_failed(np.asarray(states)[:, :2])

    def path_failed(self, paths):
        return self.maze.paths_hit(paths)

    def observe(self, states, *_):
        """``(N, n_rays)`` float32 ray lengths (px) of states ``(N, 3)``."""
        return self.maze.rays(np.asarray(states, dtype=float), self.n_rays).astype(np.float32)
