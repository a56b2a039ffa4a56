"""The avoid values of the quadrotor's ``hj`` guardian (:class:`rmm_guardians.hj.quadrotor.QuadrotorHJGuardian`):
each leg's altitude bands, the grid over the leg, the cache key and the solve of each band's value,
the leg the pilot flies and the value read at a horizontal state.  The model and the grid:
:class:`~rmm_guardians.hj.quadrotor.QuadrotorHJGuardian`'s docstring.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_guardians.hj.cache import ValueCache, load_or_solve
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.grid import Grid, central_gradient
from rmm_guardians.hj.room import angle, room_target
from rmm_guardians.hj.solver import select_backend, solve_brt

__all__ = ["LegValues"]


class LegValues:
    """The values part of the quadrotor's HJ guardian, which sets the arguments read here."""

    spacing: float
    n_heading: int
    n_speed: int
    v_max: float
    horizon: float
    pad: float | None
    band_margin: float
    reach: float
    order: int
    rk: int
    cfl: float
    backend: str
    threads: int | None
    cache: ValueCache | None
    dynamics: Dubins4DHJ
    solve_seconds: float
    _counts: dict
    waypoints: np.ndarray
    leg: int
    _legs: list[list[tuple]]
    z_band: tuple[float, float]
    grid: Grid
    V: np.ndarray | None
    _interp: Callable

    def band(self, a, b) -> tuple[float, float]:
        """The altitude band ``(z_lo, z_hi)`` of the leg from point ``a`` to ``b`` (module docstring)."""
        return min(float(a[2]), float(b[2])) - self.band_margin, max(float(a[2]), float(b[2])) + self.band_margin

    def region_grid(self, room, a, b) -> Grid:
        """The grid over the box of the leg from ``a`` to ``b`` plus ``pad``, clipped to the walls'
        extent (``pad=None``: the walls' extent, the whole room)."""
        pts = np.array([[float(a[0]), float(a[1])], [float(b[0]), float(b[1])]])
        lo_w, hi_w = room.bounds()
        if self.pad is None:
            lo, hi = np.minimum(lo_w[:2], pts.min(0) - self.spacing), np.maximum(hi_w[:2], pts.max(0) + self.spacing)
        else:
            lo = np.maximum(pts.min(0) - self.pad, np.minimum(lo_w[:2], pts.min(0) - self.spacing))
            hi = np.minimum(pts.max(0) + self.pad, np.maximum(hi_w[:2], pts.max(0) + self.spacing))
        n = [max(3, int(math.ceil((hi[k] - lo[k]) / self.spacing)) + 1) for k in range(2)]
        return Grid(
            [lo[0], lo[1], -math.pi, 0.0],
            [hi[0], hi[1], math.pi, self.v_max],
            [n[0], n[1], self.n_heading, self.n_speed],
            periodic=[2],
        )

    def spec(self, room, grid: Grid, z_lo: float, z_hi: float) -> dict:
        walls = np.asarray(room.walls, float).reshape(-1, 6)
        objects = [
            [o["shape"], *(np.round(np.asarray(o[k], float), 9).tolist() for k in ("pos", "quat", "size"))]
            for o in room.objects
        ]
        return {
            "system": "quadrotor-horizontal",
            "dynamics": self.dynamics.key(),
            "grid": grid.key(),
            "horizon": self.horizon,
            "order": self.order,
            "rk": self.rk,
            "cfl": self.cfl,
            "band": [round(z_lo, 9), round(z_hi, 9)],
            "radius": BOUND,
            "walls": np.round(walls, 9).tolist(),
            "objects": objects,
            "version": 2,
        }

    def value_function(self, room, grid: Grid, z_lo: float, z_hi: float) -> np.ndarray:
        """The avoid value of the room's cross-sections at the band on ``grid`` (cached)."""

        def solve():
            return solve_brt(
                grid,
                self.dynamics,
                room_target(grid, room, z_lo, z_hi),
                self.horizon,
                order=self.order,
                rk=self.rk,
                cfl=self.cfl,
                backend=self.backend,
                threads=self.threads,
            )[0]

        V, seconds = load_or_solve(
            self.cache or None, self.spec(room, grid, z_lo, z_hi), grid.shape, solve, self._counts
        )
        if seconds is not None:
            self.solve_seconds += seconds
        return V

    def leg_values(self, room, points) -> list[list[tuple]]:
        """Per leg between consecutive ``points``: its values ``(band, grid, V, interpolator of V and
        its gradient)``, the whole band's first, then the arrival band's where the leg climbs or
        descends by more than ``2 band_margin`` (a narrower band: a value of its own)."""
        legs = []
        for a, b in zip(points[:-1], points[1:], strict=True):
            grid = self.region_grid(room, a, b)
            select_backend(grid, self.dynamics, self.order, self.backend)
            bands = [self.band(a, b)]
            if abs(float(b[2]) - float(a[2])) > 2.0 * self.band_margin:
                bands.append((float(b[2]) - 1.5 * self.band_margin, float(b[2]) + 1.5 * self.band_margin))
            values = []
            for band in bands:
                V = self.value_function(room, grid, *band)
                values.append((band, grid, V, grid.interpolator([V, *central_gradient(V, grid)])))
            legs.append(values)
        return legs

    def _next_leg(self, state) -> None:
        """Follow the pilot's leg: past a waypoint within ``reach`` of it, as the pilot counts."""
        leg = max(self.leg, 0)
        while leg < len(self.waypoints) - 1 and math.dist(tuple(state[:3]), tuple(self.waypoints[leg])) < self.reach:
            leg += 1
        self.leg = leg
        values = self._legs[leg]
        # the arrival band's value once the height is within 1.5 band_margin of the waypoint's: the pilot's
        # vertical command (kept by the guardian) takes it monotonically to the waypoint's height
        arrived = len(values) > 1 and abs(float(state[2]) - float(self.waypoints[leg][2])) <= 1.5 * self.band_margin
        self.z_band, self.grid, self.V, self._interp = values[1 if arrived else 0]

    def evaluate(self, x, y, vx, vy) -> np.ndarray:
        """``(V, dV/dx, dV/dy, dV/dtheta, dV/dv)`` at position ``(x, y)`` and world velocity
        ``(vx, vy)`` (a speed above the grid's ``v_max`` is read at ``v_max``)."""
        th = angle(vy, vx)
        return self._interp(np.array([x, y, th, min(math.sqrt(vx * vx + vy * vy), self.v_max)]))

    def inside(self, x, y, vx, vy) -> bool:
        return bool(self.grid.contains(np.array([x, y, 0.0, min(math.sqrt(vx * vx + vy * vy), self.v_max)])))
