"""Grid Hamilton-Jacobi reachability: grid, dynamics, level-set solver, cache, guardian."""

from guardians.hj.grid import Grid
from guardians.hj.solver import solve_brt

__all__ = ["Grid", "solve_brt"]
