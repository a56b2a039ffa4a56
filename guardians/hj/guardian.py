"""The grid Hamilton-Jacobi reachability guardian (``hj``).

Uses **privileged** information: the obstacles at reset and the true state every step.

Arguments: ``grid`` (a :class:`Grid`) or ``grid_n`` (points per axis of the default box),
``horizon`` (4 s), ``order`` (1: upwind, 2: ENO2), ``rk`` (TVD RK order), ``cfl``, ``margin``
(take control when ``V <= margin``; 0 is the paper's rule), ``disturbance`` (bound on the
position-rate disturbance, 0 as the paper ran), ``cache_dir``/``cache``/``cache_max_files``,
``backend`` (``"auto"``: the compiled numba kernel where it applies, i.e. ``order=1``; or
``"numpy"``/``"numba"``; both give the same value to float32 rounding, so they share cache
entries).

At reset it computes (or loads from the cache) the backward reachable tube of **all** the
episode's obstacles for the Dubins4D dynamics over the horizon (4 s), on the default grid
``x, y in [-15, 15]`` (64 points each), heading periodic with period 2 pi (32 points), speed
``v in [0, 4]`` (32 points; the paper's grid, although the environment holds ``v <= 2``).  The
target is the exact signed distance to the union of the circles.  It then precomputes the
value's gradient.  That reset time is reported as the episode's ``precompute_time`` and, as in
the paper's reported HJ row, is not charged to the episode's clock unless asked.

Each step: ``V`` and ``grad V`` at the true state by multilinear interpolation (heading
wrapped onto the periodic axis).  If ``V <= margin`` the guardian takes control with the
optimal bang-bang control (``u1 = +-0.25`` by the sign of ``dV/dtheta``, ``u2 = +-0.5`` by the
sign of ``dV/dv``), otherwise the driver keeps control.

Goal-aware variant (``mode="reach_avoid"``): it also solves the reach-avoid value of the goal
over ``ra_horizon`` (10 s; the obstacles as a state constraint).  ``V_ra <= 0`` marks states
that can reach the goal within that time without a collision.  The avoid rule above still
comes first; otherwise, when the state is at the edge of the reach-avoid set
(``-ra_margin <= V_ra <= 0``), the guardian steers with the reach-avoid optimal control
(which minimises ``V_ra``) so as not to lose it.  It costs a second, 2.5x longer solve
(cached likewise).  First-order Lax-Friedrichs is diffusive over a long reach horizon: on
coarse grids the reach-avoid set is under-estimated (conservative).  For a state 3 m behind
the goal's centre at 1 m/s, with a 4 s horizon, the value (about -1 exactly) is -0.04, -0.39
and -0.54 on 33, 65 and 97 points per position axis.  Use finer grids or ``order=2`` where
it matters.

Explicit edge cases: a state outside the grid's position/speed box has no value: the guardian
leaves control to the driver and counts it (``stats()["outside_grid"]``); a state with NaN
brakes at maximum and is counted (``nan_states``); an obstacle whose centre lies outside the
grid is refused at reset (``ValueError``).  The original used only the first obstacle, padded
its periodic axis to a period of 2 pi + 0.2 and stopped acting once the heading wound past
about +-pi (REFERENCE 2.3, P8); none of that applies here.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

from guardians.base import Guardian, active_action, inactive_action
from guardians.hj.cache import ValueCache
from guardians.hj.dynamics import Dubins4DHJ
from guardians.hj.grid import Grid
from guardians.hj.solver import select_backend, solve_brt

__all__ = ["HJGuardian", "default_grid", "obstacle_target"]


def default_grid(n=(64, 64, 32, 32), half_width: float = 15.0, v_max: float = 4.0) -> Grid:
    return Grid([-half_width, -half_width, -np.pi, 0.0], [half_width, half_width, np.pi, v_max], n, periodic=[2])


def obstacle_target(grid: Grid, obstacles: np.ndarray) -> np.ndarray:
    """Signed distance to the union of circles, broadcast over heading and speed (float32)."""
    X, Y = grid.coord(0), grid.coord(1)
    l = np.full((grid.n[0], grid.n[1], 1, 1), np.inf)
    for ox, oy, r in obstacles:
        l = np.minimum(l, np.sqrt((X - ox) ** 2 + (Y - oy) ** 2) - r)
    return np.broadcast_to(l, grid.shape).astype(np.float32)


def _gradient(V: np.ndarray, grid: Grid) -> list[np.ndarray]:
    """Central differences in float32 (one-sided at non-periodic edges, as ``np.gradient``)."""
    out = []
    for ax in range(grid.ndim):
        n = V.shape[ax]

        def sl(a, b):
            s = [slice(None)] * V.ndim
            s[ax] = slice(a, b)
            return tuple(s)

        g = np.empty_like(V, dtype=np.float32)
        inv2 = np.float32(0.5 / grid.dx[ax])
        np.subtract(V[sl(2, n)], V[sl(0, n - 2)], out=g[sl(1, n - 1)])
        if grid.periodic[ax]:
            np.subtract(V[sl(1, 2)], V[sl(n - 1, n)], out=g[sl(0, 1)])
            np.subtract(V[sl(0, 1)], V[sl(n - 2, n - 1)], out=g[sl(n - 1, n)])
            g *= inv2
        else:
            g[sl(1, n - 1)] *= inv2
            inv = np.float32(1.0 / grid.dx[ax])
            np.multiply(V[sl(1, 2)] - V[sl(0, 1)], inv, out=g[sl(0, 1)])
            np.multiply(V[sl(n - 1, n)] - V[sl(n - 2, n - 1)], inv, out=g[sl(n - 1, n)])
        out.append(g)
    return out


class HJGuardian(Guardian):
    name = "hj"
    observation_type = "global"
    privileged = True

    def __init__(self, grid: Grid | None = None, grid_n=None, horizon: float = 4.0, order: int = 1, rk: int = 2, cfl: float = 0.8,
                 margin: float = 0.0, disturbance: float = 0.0, cache_dir=None, cache: bool = True, cache_max_files: int = 64,
                 mode: str = "avoid", ra_horizon: float = 10.0, ra_margin: float = 0.5, backend: str = "auto") -> None:
        super().__init__()
        if not horizon > 0:
            raise ValueError(f"horizon must be > 0, got {horizon}")
        if mode not in ("avoid", "reach_avoid"):
            raise ValueError(f"mode must be 'avoid' or 'reach_avoid', got {mode!r}")
        if not (ra_horizon > 0 and ra_margin >= 0):
            raise ValueError(f"ra_horizon must be > 0 and ra_margin >= 0, got {ra_horizon}, {ra_margin}")
        self.mode, self.ra_horizon, self.ra_margin = mode, float(ra_horizon), float(ra_margin)
        if grid is not None and grid_n is not None:
            raise ValueError("give grid or grid_n, not both")
        self.grid = grid or (default_grid(tuple(int(k) for k in grid_n)) if grid_n is not None else default_grid())
        self.horizon = float(horizon)
        self.order, self.rk, self.cfl = int(order), int(rk), float(cfl)
        self.margin = float(margin)
        self.dynamics = Dubins4DHJ(d_max=float(disturbance))
        self.backend = backend
        select_backend(self.grid, self.dynamics, self.order, backend)  # a bad choice fails here, not at reset
        self.cache = ValueCache(cache_dir, cache_max_files) if cache else None
        self._counts = {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}
        self.solve_seconds = 0.0
        self.V = None

    def spec(self, obstacles, goal=None) -> dict:
        spec = {"dynamics": self.dynamics.key(), "grid": self.grid.key(), "horizon": self.horizon, "order": self.order,
                "rk": self.rk, "cfl": self.cfl, "obstacles": np.round(np.asarray(obstacles, float), 9).tolist(), "version": 1}
        if goal is not None:  # the reach-avoid value: goal and its own horizon
            spec |= {"mode": "reach_avoid", "goal": np.round(np.asarray(goal, float), 9).tolist(), "horizon": self.ra_horizon}
        return spec

    def value_function(self, obstacles, goal=None) -> np.ndarray:
        """The avoid value of the obstacles (``goal=None``) or the reach-avoid value of the goal."""
        obstacles = np.asarray(obstacles, float).reshape(-1, 3)
        for ox, oy, r in obstacles:
            if not (self.grid.lo[0] <= ox <= self.grid.hi[0] and self.grid.lo[1] <= oy <= self.grid.hi[1]):
                raise ValueError(
                    f"obstacle centred at ({ox:.2f}, {oy:.2f}) lies outside the HJ grid "
                    f"[{self.grid.lo[0]}, {self.grid.hi[0]}] x [{self.grid.lo[1]}, {self.grid.hi[1]}]"
                )
        key = ValueCache.key(self.spec(obstacles, goal)) if self.cache else None
        V = self.cache.load(key, self.grid.shape) if self.cache else None
        if V is not None:
            self._counts["cache_hits"] += 1
            return V
        t0 = time.perf_counter()
        if goal is None:
            V, _ = solve_brt(self.grid, self.dynamics, obstacle_target(self.grid, obstacles), self.horizon,
                             order=self.order, rk=self.rk, cfl=self.cfl, backend=self.backend)
        else:
            V, _ = solve_brt(self.grid, self.dynamics, obstacle_target(self.grid, np.asarray(goal, float).reshape(1, 3)),
                             self.ra_horizon, order=self.order, rk=self.rk, cfl=self.cfl,
                             constraint=obstacle_target(self.grid, obstacles), backend=self.backend)
        self.solve_seconds = time.perf_counter() - t0
        self._counts["solves"] += 1
        if self.cache:
            try:
                self.cache.save(key, V)
            except OSError as e:  # a cache is an optimisation: a full disk must not end the episode
                self._counts["cache_errors"] = self._counts.get("cache_errors", 0) + 1
                warnings.warn(f"HJ value cache not written ({e}); continuing without it", RuntimeWarning, stacklevel=2)
        return V

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self._counts = {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}
        priv = self._privileged()
        self.V = self.value_function(priv["obstacles"])
        self.grads = _gradient(self.V, self.grid)
        self._arrays = [self.V, *self.grads]
        self._ra_arrays = None
        if self.mode == "reach_avoid":
            V_ra = self.value_function(priv["obstacles"], goal=priv["goal"])
            self._ra_arrays = [V_ra, *_gradient(V_ra, self.grid)]

    def evaluate(self, state) -> np.ndarray:
        """``(V, dV/dx, dV/dy, dV/dtheta, dV/dv)`` at ``state``."""
        return self.grid.interp_many(self._arrays, np.asarray(state, float))

    def act(self, observation, info=None):
        s = np.asarray(self._privileged()["state"], float)
        if not np.all(np.isfinite(s)):
            self._counts["nan_states"] += 1
            return active_action(0.0, -self.dynamics.u2_max)
        if not self.grid.contains(s):
            self._counts["outside_grid"] += 1
            return inactive_action()
        vals = self.evaluate(s)
        if vals[0] <= self.margin:  # safety first: the avoid value
            u1, u2 = self.dynamics.optimal_control(s, vals[1:])
            return active_action(u1, u2)
        if self._ra_arrays is not None:
            ra = self.grid.interp_many(self._ra_arrays, s)
            if -self.ra_margin <= ra[0] <= 0.0:  # at the edge of the reach-avoid set: steer to the goal
                self._counts["reach_avoid_steps"] = self._counts.get("reach_avoid_steps", 0) + 1
                u1, u2 = self.dynamics.optimal_control(s, ra[1:], control="min")
                return active_action(u1, u2)
        return inactive_action()

    def stats(self) -> dict:
        return dict(self._counts, solve_seconds=self.solve_seconds)
