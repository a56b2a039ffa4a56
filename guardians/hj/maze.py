"""The ``hj`` guardian on the maze car (``Dubins3DMazeParallel-v0``): a 3-D avoid value over the walls.

``hj`` serves both systems: :class:`guardians.hj.guardian.HJGuardian` hands an env whose action
space has the maze car's single control (``turnrate_ctrl``) to :class:`MazeHJGuardian`, which
can also be used (and named, ``guardians.hj.maze:MazeHJGuardian``) on its own.  It uses
**privileged** information: the maze, the goal, the true pose and the car's speed (the env's
``privileged()``).

## The value function

The car has a constant speed ``s`` (10 px/s) and a bounded turn rate ``|u| <= u_max`` (0.2
rad/s), read at ``reset`` from the action space.  Its backward reachable tube of the walls over
``horizon`` seconds is solved on a grid ``(x, y, psi)``, heading periodic.  The target is the
exact signed distance to the walls' surfaces (:meth:`rmm_envs.worlds.mazes.Maze.point_clearance`,
capped at 60 px far from every wall, where it never decides anything), so ``V`` is in pixels:
the closest the car can be kept to a wall over the horizon.

The solve reuses the Dubins4D solver and its compiled kernels unchanged: the constant-speed car
*is* the Dubins4D car at a fixed speed with no acceleration, so the grid gets a speed axis of
three nodes, all at ``s`` (``Dubins4DHJ(u1_max=u_max, u2_max=0, v_min=v_max=s)``); its
Hamiltonian and dissipation along that axis are exactly zero and every speed slice holds the
same 3-D value.  That costs 3x the nodes of a dedicated 3-D kernel and no new numerical code.

Defaults, and why:

* ``spacing = 8`` px between position nodes: under a wall's thickness (12.5 px), so every wall
  has a node inside it; the distance rule's margin is half of it (4 px).
* ``n_heading = 32``: 11.25 degrees, 2.2 s of full turn between nodes.
* ``horizon = 20`` s: the avoid set has converged to a point.  On a 10 x 10 maze (seed 0,
  ENO2/RK3) the unsafe share of the grid is 22.9%, 26.4%, 28.2%, 29.3%, 29.9% and 30.0% for
  horizons of 5, 10, 15, 20, 30 and 40 s: a half turn takes pi / u_max = 15.7 s, and past
  20 s almost nothing more is doomed; 20 s costs half of 40 s.
* ``region = "route"``: the grid covers the cells of the maze path from the car's cell to the
  goal's, plus ``route_margin = 1`` cell around their bounding box (the guardian computes the
  path itself from the privileged maze, pose and goal, :func:`rmm_envs.worlds.mazes.cell_path`).
  The driver keeps to that path, so this is where the value is needed, and it is about a third
  of a 10 x 10 maze.  Outside the grid the guardian leaves control to the driver and counts it
  (``stats()["outside_grid"]``).  ``region = "maze"`` covers the whole maze.
* scheme ``order = 2, rk = 3, cfl = 0.8``: ``hj``'s (see :mod:`guardians.hj.guardian`).

## Why the value alone collided

With the rule below replaced by acting on the value (``rule="distance"``: take control when
``V <= margin + s T`` and turn by the sign of ``dV/dpsi``), ``hj`` collided in 16.4% of 128
episodes (seed 0).  In those collisions the guardian is in control from ``V`` about 6 px on, and
``V`` falls under its own "optimal" turn until the car touches a wall: at seed 1214021410 it
takes over at ``(334.3, 869.5, -2.3)`` with ``V = 6.0`` px and turns right for 9 s into the
wall, while holding right for 2.5 s and then left keeps 2.2 px of clearance (a search over
one-switch manoeuvres on the exact walls).  It is the resolution, not the latency: a maze cell
leaves the car 6.25 px either side of a 100-px turning circle, the walls are 1.5 position cells
thick, and the value's errors at 8 px x 11.25 degrees are of that size both ways (over-stated at
wall ends, under-stated in dead ends, where the car can circle for ever with ``V = -3`` px).
Finer grids, more headings, longer horizons and larger margins did not remove them (earlier
runs: 8-11 of 11 collisions of 64 episodes remained), and a gradient's sign decides the turn
exactly where the two turns are nearly as good.

## The rule (``rule="lookahead"``, the default)

Decisions are checked on the true walls over a short future, and the value only beyond it.
:mod:`guardians.hj.maze_lookahead` scores two-turn manoeuvres (``u1`` for ``t1`` in
``lookahead / 6`` steps up to ``lookahead = 6`` s, then ``u2``): the least exact clearance along
the path; a manoeuvre whose second turn is a full-rate turn is followed for a **whole loop**
(31.4 s), and a loop that is clear all round is safe for ever, so it needs no value; one that
ends straight also counts ``V - value_error`` at its end pose (``value_error = 6`` px: the
value's over-statement seen above, 6-8 px, so that the value is trusted only where it is
clearly positive).  With the one-lap latency (``delay = 1``), the decision at ``s_k`` cannot
change the lap to ``s_{k+1}``: it runs under the guardian's last turn rate, or the driver's
(``info["nominal_control"]``, exactly what the driver applies then).  The guardian stays
passive when that lap, one more lap of the driver's turn rate, and then the best manoeuvre all
keep more than ``margin`` (``None``: half a position cell, 4 px) of clearance.  Otherwise it
commands, from the pose one lap ahead, the **least invasive** manoeuvre that keeps ``margin``:
the one whose first turn rate is nearest the driver's (ties: the larger score), and the
best-scoring one when none does.  Where the value exceeds ``band`` (20 px, past the 8 px of
over-statement seen) no manoeuvre is scored: the car is far from every wall and the driver
keeps control.

How it was chosen, on 32 development episodes of ``--seed 5`` (fixed 1 ms clock; the driver
alone collides in about half): the value-only rule below, 4 collisions and 1 timeout; the
look-ahead taking the best-scoring manoeuvre, 1 collision and 6 timeouts (it turned the car
round in corridors and the driver turned it back); the least invasive one, 1 collision and 2
timeouts; the same with ``value_error = 6``, no collision and 2 timeouts (30 goals), the
default.  Requiring instead that each turn rate leave a checked manoeuvre one lap later
collided twice in the first 23 (a turn's checked manoeuvres need not be there one lap on:
``t1`` moves in 1-s steps), so the simpler rule stays.

``rule="distance"`` keeps the value-only rule above (``hj``'s Dubins4D rule): the decision
commits ``T = (1 + delay) lap`` s and ``V`` is 1-Lipschitz in position, so it takes control when
``V <= margin + s T`` (6.2 px at 0.11-s laps) with ``u = u_max sign(dV/dpsi)``.

The value is cached on disk like the Dubins4D one (:class:`guardians.hj.cache.ValueCache`; the
key holds the walls, the grid, the dynamics and the scheme).  The solve time of an episode is in
``stats()["solve_seconds"]`` and is reported as the episode's precompute time.

## Measured

``rule="distance"``: ``rmm-bench --agent hj --env Dubins3DMazeParallel-v0 --episodes 128 --clock
fixed:1`` (seed 0): 83.6% success, 16.4% collisions, no timeouts (the driver alone: 46.1%
collisions over 256), in control 8.9% of the simulated time.  A solve on the default route
grid took 6.9 s on average (3.1-15.7 s over 126 solves) on a shared, loaded 2-core machine,
one thread (not a timing benchmark: load inflates it); it is cached, so a rerun of the same
episodes reads it back.  The look-ahead rule, ``rmm-bench --agent hj --env Dubins3DMazeParallel-v0
--episodes 512 --seed 11 --clock fixed:1`` (a seed no default was chosen on): 93.9% success, no
collision, 6.1% timeouts, in control 12.9% of the simulated time (docs/reproduction.md).

Explicit edge cases: a pose with NaN applies the env's safe default (the maximum turn away
from the nearer wall) to the observation and is counted (``nan_states``); a maze with no walls
is refused at reset.
"""

from __future__ import annotations

import math

import numpy as np

from guardians._checks import finite, integer
from guardians.dispatch import maze_car_only
from guardians.privileged import PrivilegedGuardian
from guardians.hj.cache import ValueCache, load_or_solve
from guardians.hj.dynamics import Dubins4DHJ
from guardians.hj.grid import Grid, central_gradient
from guardians.hj.maze_lookahead import COEF, manoeuvres, near_walls, path_clearances
from guardians.hj.solver import check_scheme, select_backend, solve_brt

__all__ = ["MazeHJGuardian", "maze_grid", "wall_target"]

REGIONS = ("route", "maze")
MAZE_RULES = ("lookahead", "distance")
SAMPLE_DT = 0.2  # s between the look-ahead's path samples (2 px at 10 px/s)


def maze_grid(lo, hi, spacing: float, n_heading: int, speed: float) -> Grid:
    """The 4-D grid of the embedded problem over the box ``lo``-``hi`` (px): about ``spacing``
    px between position nodes, ``n_heading`` periodic headings and a speed axis of three nodes
    at ``speed`` (see the module docstring)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    n = [max(3, int(math.ceil((hi[k] - lo[k]) / spacing)) + 1) for k in range(2)]
    return Grid([lo[0], lo[1], -math.pi, speed], [hi[0], hi[1], math.pi, speed * (1.0 + 1e-6)],
                [n[0], n[1], n_heading, 3], periodic=[2])


def wall_target(grid: Grid, maze) -> np.ndarray:
    """Signed distance (px) from each position node to the nearest wall surface, broadcast over
    heading and speed (float32)."""
    X, Y = np.meshgrid(grid.axes[0], grid.axes[1], indexing="ij")
    d = maze.point_clearance(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    return np.broadcast_to(d[:, :, None, None], grid.shape).astype(np.float32)


class MazeHJGuardian(PrivilegedGuardian):
    """Grid HJ reachability guardian for the maze car; see the module docstring."""

    name = "hj"

    def __init__(self, spacing: float = 8.0, n_heading: int = 32, horizon: float = 20.0, region: str = "route",
                 route_margin: int = 1, order: int = 2, rk: int = 3, cfl: float = 0.8, margin: float | None = None,
                 delay: int = 1, lap: float | None = None, cache_dir=None, cache: bool = True,
                 cache_max_files: int = 64, backend: str = "auto", threads: int | None = None,
                 rule: str = "lookahead", lookahead: float = 6.0, band: float = 20.0, value_error: float = 6.0) -> None:
        super().__init__()
        if rule not in MAZE_RULES:
            raise ValueError(f"rule must be one of {MAZE_RULES}, got {rule!r}")
        self.rule = rule
        self.lookahead = finite("lookahead", lookahead, 0.0, lo_open=True)
        self.band = finite("band", band, 0.0)
        self.value_error = finite("value_error", value_error, 0.0)
        self.spacing = finite("spacing", spacing, 0.0, lo_open=True)
        self.n_heading = integer("n_heading", n_heading, 3)
        self.horizon = finite("horizon", horizon, 0.0, lo_open=True)
        if region not in REGIONS:
            raise ValueError(f"region must be one of {REGIONS}, got {region!r}")
        self.region = region
        self.route_margin = integer("route_margin", route_margin, 0, "cells around the route's bounding box")
        self.order, self.rk, self.cfl = check_scheme(order, rk, cfl)
        self.margin = None if margin is None else finite("margin", margin)
        self.delay = integer("delay", delay, 0, "laps between a decision and its effect")
        self.lap = None if lap is None else finite("lap", lap, 0.0, lo_open=True)
        self.threads = None if threads is None else integer("threads", threads, 1, "or None")
        if backend not in ("auto", "numpy", "numba"):
            raise ValueError(f"backend must be one of ('auto', 'numpy', 'numba'), got {backend!r}")
        self.backend = backend
        self.cache = ValueCache(cache_dir, integer("cache_max_files", cache_max_files, 1)) if cache else None
        self._counts = self._zero()
        self.solve_seconds = 0.0
        self.V = None

    @staticmethod
    def _zero() -> dict:
        return {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}

    # ------------------------------------------------------------------ applicability
    def check_spaces(self, observation_space, action_space) -> None:
        maze_car_only(self, action_space)

    # ------------------------------------------------------------------ the value
    def region_box(self, maze, state, goal) -> tuple[np.ndarray, np.ndarray]:
        """The grid's position box (px): the route's cells plus ``route_margin`` cells (``region
        = "route"``), or the walls' extent (``"maze"``), clipped to the walls' extent."""
        w = maze.walls
        lo = np.minimum(w[:, :2].min(0), w[:, 2:].min(0))
        hi = np.maximum(w[:, :2].max(0), w[:, 2:].max(0))
        if self.region == "maze" or maze.cells.shape[0] < 2:
            return lo, hi
        from rmm_envs.worlds.mazes import cell_of, cell_path

        path = cell_path(maze, cell_of(maze, state), cell_of(maze, goal))
        a, b = np.asarray(maze.passages[0], dtype=int)
        cell = float(np.hypot(*(maze.cells[a] - maze.cells[b])))
        pts = maze.cells[path]
        pad = (0.5 + self.route_margin) * cell
        return np.maximum(lo, pts.min(0) - pad), np.minimum(hi, pts.max(0) + pad)

    def spec(self, maze, grid: Grid) -> dict:
        return {"system": "maze-car", "dynamics": self.dynamics.key(), "grid": grid.key(), "horizon": self.horizon,
                "order": self.order, "rk": self.rk, "cfl": self.cfl, "thickness": float(maze.thickness),
                "walls": np.round(np.asarray(maze.walls, float), 6).tolist(), "version": 1}

    def value_function(self, maze, grid: Grid) -> np.ndarray:
        """The avoid value of the maze's walls on ``grid`` (from the cache when there)."""
        def solve():
            return solve_brt(grid, self.dynamics, wall_target(grid, maze), self.horizon, order=self.order, rk=self.rk,
                             cfl=self.cfl, backend=self.backend, threads=self.threads)[0]

        V, seconds = load_or_solve(self.cache or None, self.spec(maze, grid), grid.shape, solve, self._counts)
        if seconds is not None:
            self.solve_seconds = seconds
        return V

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        space = self.action_space
        priv = self._privileged()
        maze = priv["maze"]
        if np.asarray(maze.walls).shape[0] == 0:
            raise ValueError(f"guardian {self.name!r} (maze) needs a maze with walls, got none")
        state = np.asarray(priv["state"], float)
        if "speed" not in priv:
            raise ValueError(f"guardian {self.name!r} (maze) needs the car's speed in the env's privileged data "
                             f"(keys: {sorted(priv)})")
        self.speed = finite("privileged speed", priv["speed"], 0.0, lo_open=True)
        self.u_max = float(space.control_high[0])
        self.dynamics = Dubins4DHJ(u1_max=self.u_max, u2_max=0.0, v_min=self.speed, v_max=self.speed)
        self._counts = self._zero()
        self.solve_seconds = 0.0
        lo, hi = self.region_box(maze, state, np.asarray(priv["goal"], float))
        self.grid = maze_grid(lo, hi, self.spacing, self.n_heading, self.speed)
        select_backend(self.grid, self.dynamics, self.order, self.backend)
        self.V = self.value_function(maze, self.grid)
        self._arrays = [self.V, *central_gradient(self.V, self.grid)[:3]]
        self._margin = 0.5 * float(max(self.grid.dx[0], self.grid.dx[1])) if self.margin is None else self.margin
        self._safe = space.safe_default.policy(space, self.rng) if space.safe_default is not None else None
        self.start_laps()
        self._maze_geom = (np.ascontiguousarray(np.asarray(maze.walls, float)), float(maze.half), float(maze.width),
                           float(maze.height))
        self._manoeuvres = manoeuvres(self.u_max, self.lookahead)
        self._pending = None  # the turn rate the guardian commanded last step (None: it was inactive)

    # ------------------------------------------------------------------ the decision
    def evaluate(self, state) -> np.ndarray:
        """``(V, dV/dx, dV/dy, dV/dpsi)`` at pose ``state``."""
        x, y, psi = (float(s) for s in state[:3])
        return self.grid.interp_many(self._arrays, np.array([x, y, psi, self.speed]))

    def threshold(self) -> float:
        """The value at or below which the guardian takes control."""
        return self._margin + self.speed * (1 + self.delay) * self.current_lap()

    def act(self, observation, info=None):
        s = self._state_and_lap()
        self._pending, pending = None, self._pending
        if not self.finite_state(s):
            u = self._safe(observation) if self._safe is not None else self.action_space.control_high
            return self.action_space.active(u)
        psi = (s[2] + math.pi) % (2 * math.pi) - math.pi
        if not self.grid.contains(np.array([s[0], s[1], psi, self.speed])):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        if self.rule == "distance":
            vals = self.evaluate((s[0], s[1], psi))
            if vals[0] <= self.threshold():
                return self.action_space.active(np.array([self.u_max if vals[3] >= 0 else -self.u_max]))
            return self.action_space.inactive()
        nominal = _turn_rate(info, "nominal_control")
        if pending is None and self.evaluate((s[0], s[1], psi))[0] > self.band:
            return self.action_space.inactive()  # far from every wall's reach: no look-ahead needed
        u = self._lookahead_decision(s[0], s[1], psi, nominal, pending)
        self._pending = u
        return self.action_space.inactive() if u is None else self.action_space.active(np.array([u]))

    def _scores(self, x, y, psi, man=None) -> tuple[np.ndarray, np.ndarray]:
        """Each manoeuvre's score from pose ``(x, y, psi)`` (module docstring of
        :mod:`guardians.hj.maze_lookahead`) and its end pose."""
        man = self._manoeuvres if man is None else man
        walls, half, width, height = self._maze_geom
        reach = self.speed * self.lookahead + 2.0 * self.speed / self.u_max + 2 * self.spacing
        near = near_walls(walls, x, y, reach, half)
        clear = np.empty(man.shape[0])
        ends = np.empty((man.shape[0], 3))
        path_clearances(x, y, psi, self.speed, man, SAMPLE_DT, near, half, width, height, COEF, clear, ends)
        for m in range(man.shape[0]):
            if man[m, 2] != 0.0:  # ends in a whole loop: clear all round, it is safe for ever
                continue
            e = ends[m]
            p = (e[2] + math.pi) % (2 * math.pi) - math.pi
            if clear[m] > 0 and self.grid.contains(np.array([e[0], e[1], p, self.speed])):
                V = float(self.grid.interp_many([self.V], np.array([e[0], e[1], p, self.speed]))[0])
                clear[m] = min(clear[m], V - self.value_error)
        return clear, ends

    def _hold(self, x, y, psi, u, duration):
        """The least clearance over ``duration`` s holding turn rate ``u``, and the end pose."""
        man = np.array([[u, 0.0, u, duration]])
        walls, half, width, height = self._maze_geom
        near = near_walls(walls, x, y, self.speed * duration + 2 * self.spacing, half)
        clear, ends = np.empty(1), np.empty((1, 3))
        path_clearances(x, y, psi, self.speed, man, min(SAMPLE_DT, duration), near, half, width, height, COEF, clear, ends)
        return float(clear[0]), ends[0]

    def _lookahead_decision(self, x, y, psi, nominal, held):
        """The turn rate to command, or ``None`` to leave the driver in control (module
        docstring); ``held``: the turn rate commanded last step (``None``: the driver's)."""
        lap = self.current_lap()
        pending = held if held is not None else nominal
        c0, p1 = self._hold(x, y, psi, pending, lap * self.delay) if self.delay else (np.inf, np.array([x, y, psi]))
        margin = self._margin
        c1, p2 = self._hold(*p1, nominal, lap)  # one more lap of the driver, then the best recovery
        if min(c0, c1, float(self._scores(*p2)[0].max())) > margin:
            return None
        scores, _ = self._scores(*p1)
        man = self._manoeuvres
        first = np.where(man[:, 1] > 0, man[:, 0], man[:, 2])
        safe = np.flatnonzero(scores > margin)
        if safe.size:  # the least invasive safe manoeuvre: first turn nearest the driver's, then the safest
            key = np.abs(first[safe] - nominal)
            near = safe[key <= key.min() + 1e-12]
            return float(first[near[np.argmax(scores[near])]])
        return float(first[int(np.argmax(scores))])

    def stats(self) -> dict:
        return dict(self._counts, solve_seconds=self.solve_seconds)


def _turn_rate(info, key: str) -> float:
    """The turn rate ``info[key]`` (the env's documented ``nominal_control``), refused (naming
    it) when missing or not one finite number."""
    if not isinstance(info, dict) or key not in info:
        raise ValueError(f"guardian 'hj' (maze, rule='lookahead') needs info[{key!r}] from the env "
                         f"(got keys {sorted(info) if isinstance(info, dict) else type(info).__name__})")
    u = np.asarray(info[key], float).reshape(-1)
    if u.shape != (1,) or not math.isfinite(float(u[0])):
        raise ValueError(f"info[{key!r}] must be one finite turn rate, got {info[key]!r}")
    return float(u[0])
