"""Input bounds shared by the maps, the reset options and the maze generator.

Every number a user gives a world (a coordinate, a radius, a speed, a thickness) must be
finite **and** at most :data:`MAX_MAGNITUDE` in absolute value: the geometry squares and
multiplies these numbers (distances, ray casts, discriminants), so a finite value of 1e200
would still make observations ``inf`` or ``NaN``.  1e9 (a million kilometres, or pixels) is far
beyond any scene of this package, and its fourth power is still far from overflow.

Sizes are bounded too, before anything is allocated: a map file's bytes
(:data:`MAX_MAP_BYTES`), a polygon's vertices (:data:`MAX_POLYGON_VERTICES`) and a maze's
rows and columns (:data:`MAX_MAZE_SIDE`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MAX_MAGNITUDE", "MAX_MAP_BYTES", "MAX_MAZE_SIDE", "MAX_POLYGON_VERTICES", "within_bounds"]

MAX_MAGNITUDE = 1e9
MAX_MAP_BYTES = 16 * 2**20  # 16 MiB of JSON: some 500,000 vertices
MAX_POLYGON_VERTICES = 5_000  # the simplicity check compares every pair of edges: about 2 s at this size
MAX_MAZE_SIDE = 32  # rows or columns of a generated maze: its collision buckets take time and memory growing with
#                      the fourth power of the side (measured: 30 x 30, 3 s and 0.56 GB; 50 x 50, 17 s and 3.2 GB)


def within_bounds(values) -> bool:
    """Whether every value (a number, a nested list of numbers or an array) is a finite number of
    magnitude at most :data:`MAX_MAGNITUDE`.  Python integers are compared before any
    conversion, so ``10**400`` is refused instead of overflowing a float conversion."""
    if isinstance(values, np.ndarray):
        if values.dtype.kind in "biuf":
            return bool(np.all(np.abs(values.astype(float)) <= MAX_MAGNITUDE))  # NaN compares False
        return all(within_bounds(v) for v in values.ravel().tolist())
    if isinstance(values, (list, tuple)):
        return all(within_bounds(v) for v in values)
    if isinstance(values, (int, np.integer)):
        return abs(int(values)) <= MAX_MAGNITUDE
    try:
        return abs(float(values)) <= MAX_MAGNITUDE
    except (TypeError, ValueError, OverflowError):
        return False
