"""Grid Hamilton-Jacobi reachability: grid, dynamics, level-set solver, cache, guardian."""

from rmm_guardians.hj.grid import Grid
from rmm_guardians.hj.solver import solve_brt

__all__ = ["Grid", "solve_brt"]
