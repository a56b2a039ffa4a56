"""A Dubins3D car in one maze: :class:`MazeScene`."""

from __future__ import annotations

import numpy as np

from rmm_envs.scenes.base import SceneBase, branch_inputs
from rmm_envs.scenes.branch_kernels import dubins3d_maze_branches
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.mazes import Maze

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

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``path_failed(propagate(...))`` and the paths' last poses, one branch at a time in a
        compiled loop (:func:`~rmm_envs.scenes.branch_kernels.dubins3d_maze_branches`, the same
        bits, against the same candidate walls); a subclass that changes the dynamics, the maze's
        ``paths_hit``, ``propagate`` or ``path_failed`` gets the composition of its own."""
        if (
            type(self.dynamics) is not Dubins3D
            or type(self.maze) is not Maze
            or type(self).propagate is not SceneBase.propagate
            or type(self).path_failed is not MazeScene.path_failed
        ):
            return super().propagate_failed(states, controls, duration, n_steps)
        states, controls, times = branch_inputs(states, controls, duration, n_steps, 3, 1)
        maze, dyn = self.maze, self.dynamics
        cand = maze._candidates(states[:, :2])  # the walls near each path's first point, as paths_hit takes them
        failed, ends = np.empty(states.shape[0], dtype=bool), np.empty((states.shape[0], 3))
        dubins3d_maze_branches(
            states,
            controls,
            times,
            float(dyn.speed),
            float(dyn.u_max),
            maze._walls_ext,
            np.ascontiguousarray(cand),
            float(maze.half),
            float(maze.width),
            float(maze.height),
            failed,
            ends,
        )
        return failed, ends

    def observe(self, states, *_):
        """``(N, n_rays)`` float32 ray lengths (px) of states ``(N, 3)``."""
        return self.maze.rays(np.asarray(states, dtype=float), self.n_rays).astype(np.float32)
