"""Where a guarded maze episode starts: the maze (generated or given), the car's pose, the goal
cell at the stated distance and the driver's waypoints, all drawn from the episode's generator."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.envs.base import option_vector, whole
from rmm_envs.systems.maze.driver import cell_distances, cell_of, cell_path
from rmm_envs.systems.maze.env import maze_from_option
from rmm_envs.systems.maze.mazes import Maze, generate_maze

__all__ = ["MazeStarts"]


class MazeStarts:
    """The starts of :class:`rmm_envs.systems.maze.guarded.Dubins3DMazeGuardedEnv` (it sets
    ``np_random``, ``maze_shape``, ``goal_cells``, ``start_jitter`` and ``heading_noise``)."""

    np_random: np.random.Generator
    maze_shape: tuple[int, int]
    goal_cells: tuple[int, int]
    start_jitter: float
    heading_noise: float

    def _maze(self, spec) -> Maze:
        if spec is None:
            return generate_maze(self.np_random, "rectangular", *self.maze_shape)
        if isinstance(spec, Maze) and (spec.cells.shape[0] < 2 or spec.passages.shape[0] < 1):
            raise ValueError("option 'maze' must have cells joined by passages (a generated Maze); this one has none")
        return maze_from_option(spec, self.np_random)

    def _start(self, options: dict):
        rng = self.np_random
        maze = self._maze(options.get("maze"))
        n = maze.cells.shape[0]
        if "state" in options:
            state = option_vector(options["state"], 3, "state", " [x, y, psi]")
            start = cell_of(maze, state)
            a, b = np.asarray(maze.passages[0], dtype=int)
            spacing = float(np.hypot(*(maze.cells[a] - maze.cells[b])))  # between neighbouring cell centres
            if maze.state_failed(state[None, :2])[0] or np.hypot(
                *(state[:2] - maze.cells[start])
            ) > spacing / math.sqrt(2):
                raise ValueError(f"option 'state': {state[:2].tolist()} is inside a wall or outside the maze's cells")
        else:
            state, start = None, int(rng.integers(n))
        dist = cell_distances(maze, start)
        if "goal_cell" in options:
            goal = options["goal_cell"]
            if not whole(goal) or not 0 <= goal < n or int(goal) == start:
                raise ValueError(
                    f"option 'goal_cell' must be an integer cell index in [0, {n}) other than the start "
                    f"cell {start}, got {goal!r}"
                )
            goal = int(goal)
        else:
            band = np.flatnonzero((dist >= self.goal_cells[0]) & (dist <= self.goal_cells[1]))
            if band.size == 0:
                raise ValueError(
                    f"no cell of the maze is {self.goal_cells[0]}-{self.goal_cells[1]} passages from start cell "
                    f"{start} (goal_cells); give a larger maze or 'goal_cell'"
                )
            goal = int(band[rng.integers(band.size)])
        cells = cell_path(maze, start, goal)
        waypoints = maze.cells[cells]
        if state is None:
            pos = waypoints[0] + rng.uniform(-self.start_jitter, self.start_jitter, 2)
            d = waypoints[1] - waypoints[0]
            psi = math.atan2(d[1], d[0]) + rng.uniform(-self.heading_noise, self.heading_noise)
            state = np.array([pos[0], pos[1], psi])
        waypoints = np.vstack([state[None, :2], waypoints[1:]])  # from the car, through the path's cells
        return maze, state, goal, waypoints
