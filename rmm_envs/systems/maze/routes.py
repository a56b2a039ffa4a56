"""Routes through a maze's passages: the cell of a point, the passages from a cell to every other
and the cells from one to another.  A perfect maze (:func:`rmm_envs.systems.maze.mazes.generate_maze`)
is a tree of cells joined by passages, so the route between two cells is unique; the driver plans on
it and the guardians' look-ahead reads it.
"""

from __future__ import annotations

from collections import deque

import numpy as np

__all__ = ["cell_distances", "cell_of", "cell_path"]


def _neighbours(maze) -> list[list[int]]:
    nb: list[list[int]] = [[] for _ in range(maze.cells.shape[0])]
    for a, b in np.asarray(maze.passages, dtype=int):
        nb[a].append(int(b))
        nb[b].append(int(a))
    return nb


def cell_of(maze, point) -> int:
    """The cell whose centre is nearest to ``point`` (its cell, inside the maze)."""
    d = ((maze.cells - np.asarray(point, dtype=float)[:2]) ** 2).sum(axis=1)
    return int(np.argmin(d))


def cell_distances(maze, start: int) -> np.ndarray:
    """Passages from cell ``start`` to every cell (breadth-first over the maze's tree; -1 if unreachable)."""
    nb = _neighbours(maze)
    dist = np.full(maze.cells.shape[0], -1, dtype=int)
    dist[start] = 0
    queue = deque([start])
    while queue:
        a = queue.popleft()
        for b in nb[a]:
            if dist[b] < 0:
                dist[b] = dist[a] + 1
                queue.append(b)
    return dist


def cell_path(maze, start: int, goal: int) -> list[int]:
    """The cells from ``start`` to ``goal`` (both included) through the maze's passages."""
    n = maze.cells.shape[0]
    for name, c in (("start", start), ("goal", goal)):
        if not 0 <= c < n:
            raise ValueError(f"{name} cell must be in [0, {n}), got {c}")
    nb = _neighbours(maze)
    parent = {start: start}
    queue = deque([start])
    while queue and goal not in parent:
        a = queue.popleft()
        for b in nb[a]:
            if b not in parent:
                parent[b] = a
                queue.append(b)
    if goal not in parent:
        raise ValueError(f"cell {goal} cannot be reached from cell {start} through the maze's passages")
    path = [goal]
    while path[-1] != start:
        path.append(parent[path[-1]])
    return path[::-1]
