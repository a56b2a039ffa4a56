"""The ``hj`` guardian on the maze car (``Dubins3DMazeParallel-v0``): a 3-D avoid value over the walls.

:class:`rmm_guardians.hj.guardian.HJGuardian` hands an env whose action space is of the maze car's
dynamics (``"dubins3d"``) to :class:`MazeHJGuardian`, also usable (and named,
``rmm_guardians.hj.maze:MazeHJGuardian``) on its own.  It reads **privileged** data (the maze, the
goal, the true pose, the car's speed) and, at reset, solves the walls' backward reachable tube
for the constant-speed car with the Dubins4D solver (a speed axis of three equal nodes); each
step its look-ahead rule (:mod:`rmm_guardians.hj.maze_lookahead`) checks the driver's next laps and
the best two-turn recovery against the walls and the value.

Offers :class:`MazeHJGuardian` (the value, the rule and the defaults in its docstring),
:func:`maze_grid` and :func:`wall_target`.  Why, and the alternatives tried:
docs/decisions/0012-hj-maze-lookahead.md.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.maze.dynamics import CONTROLS
from rmm_envs.systems.maze.routes import cell_of, cell_path
from rmm_guardians._checks import finite, integer
from rmm_guardians.hj.cache import ValueCache, load_or_solve
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.grid import Grid, central_gradient
from rmm_guardians.hj.maze_lookahead import COEF, manoeuvres, near_walls, path_clearances
from rmm_guardians.hj.settings import disturbance_setting, env_disturbance_bound
from rmm_guardians.hj.solver import check_scheme, select_backend, solve_brt
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import maze_car_only

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
    return Grid(
        [lo[0], lo[1], -math.pi, speed],
        [hi[0], hi[1], math.pi, speed * (1.0 + 1e-6)],
        [n[0], n[1], n_heading, 3],
        periodic=[2],
    )


def wall_target(grid: Grid, maze) -> np.ndarray:
    """Signed distance (px) from each position node to the nearest wall surface, broadcast over
    heading and speed (float32)."""
    X, Y = np.meshgrid(grid.axes[0], grid.axes[1], indexing="ij")
    d = maze.point_clearance(np.column_stack([X.ravel(), Y.ravel()])).reshape(X.shape)
    return np.broadcast_to(d[:, :, None, None], grid.shape).astype(np.float32)


class MazeHJGuardian(PrivilegedGuardian):
    """Grid HJ reachability guardian for the maze car; see the module docstring.

    **Value**: the car (speed ``s``, turn rate ``|u| <= u_max``, read at ``reset`` from the
    action space) gets the backward reachable tube of the walls over ``horizon`` on a grid
    ``(x, y, psi)``, heading periodic; the target is the exact signed distance to the walls'
    surfaces (capped at 60 px), so ``V`` is in pixels.  It is solved as the Dubins4D car at one
    speed (``Dubins4DHJ(u1_max=u_max, u2_max=0, v_min=v_max=s)``, a speed axis of three nodes),
    cached on disk like the Dubins4D value; the solve time is ``stats()["solve_seconds"]`` and the
    episode's precompute time.  ``disturbance`` (0; ``hj.disturbance``, as on Dubins4D): a bound
    ``d_max`` (px/s) on the position rates ``|d_x|, |d_y|``, against the car; ``"env"``: the run's own
    ``dyn-rate`` bound, read at every reset (0 without one).  The look-ahead's paths stay nominal.

    **Rule** (``rule="lookahead"``, :mod:`rmm_guardians.hj.maze_lookahead`): two-turn manoeuvres
    (``u1`` for ``t1`` in ``lookahead / 6`` steps up to ``lookahead``, then ``u2``) are scored by
    their least exact clearance; one whose second turn is a full-rate turn is followed for a whole
    loop (a clear loop is safe for ever), one ending straight also counts ``V - value_error`` at
    its end.  It stays passive while the pending lap (under its last turn rate or the driver's
    ``info["nominal_control"]``), one more lap of the driver's turn rate and the best manoeuvre
    keep more than ``margin`` of clearance; otherwise it commands, from the pose one lap ahead,
    the manoeuvre keeping ``margin`` whose first turn rate is nearest the driver's (ties: the
    larger score), else the best-scoring one.  Where ``V`` exceeds ``band`` nothing is scored.
    ``rule="distance"``: take control when ``V <= margin + s T`` (``T = (1 + delay) lap``) with
    ``u = u_max sign(dV/dpsi)``.

    Defaults: ``spacing = 8`` px (under a wall's 12.5 px, so every wall has a node inside it);
    ``n_heading = 32`` (11.25 degrees); ``horizon = 20`` s (a half turn takes
    ``pi / u_max`` = 15.7 s; on a 10 x 10 maze the unsafe share of the grid is 22.9, 26.4, 28.2,
    29.3, 29.9 and 30.0% at 5, 10, 15, 20, 30 and 40 s, and 20 s costs half of 40);
    ``region = "route"`` (the cells of the maze path from the car to the goal plus
    ``route_margin`` cell around their bounding box, about a third of a 10 x 10 maze; outside it
    control is left to the driver, counted in ``outside_grid``; ``"maze"``: the whole maze);
    ``order = 2, rk = 3, cfl = 0.8``; ``margin`` ``None``: half a position cell (4 px);
    ``lookahead = 6`` s, ``band = 20`` px and ``value_error = 6`` px (the value's over-statement
    seen at wall ends, 6-8 px).  A pose with NaN applies the env's safe default (``nan_states``);
    a maze with no walls is refused at reset."""

    name = "hj"
    #: as a part of its method (rmm_guardians.parts): what it models, its controls, its settings field
    serves, controls, option = "the maze car", CONTROLS, "maze"

    def __init__(
        self,
        spacing: float = 8.0,
        n_heading: int = 32,
        horizon: float = 20.0,
        region: str = "route",
        route_margin: int = 1,
        order: int = 2,
        rk: int = 3,
        cfl: float = 0.8,
        margin: float | None = None,
        delay: int = 1,
        lap: float | None = None,
        cache_dir=None,
        cache: bool = True,
        cache_max_files: int = 64,
        backend: str = "auto",
        threads: int | None = None,
        rule: str = "lookahead",
        lookahead: float = 6.0,
        band: float = 20.0,
        value_error: float = 6.0,
        disturbance: float | str = 0.0,
    ) -> None:
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
        self.disturbance = disturbance_setting(disturbance)
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
        self.V: np.ndarray | None = None
        self._pose: tuple[float, float, float] | None = None  # the last decision's pose on the grid (signals())

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
        path = cell_path(maze, cell_of(maze, state), cell_of(maze, goal))
        a, b = np.asarray(maze.passages[0], dtype=int)
        cell = float(np.hypot(*(maze.cells[a] - maze.cells[b])))
        pts = maze.cells[path]
        pad = (0.5 + self.route_margin) * cell
        return np.maximum(lo, pts.min(0) - pad), np.minimum(hi, pts.max(0) + pad)

    def spec(self, maze, grid: Grid) -> dict:
        return {
            "system": "maze-car",
            "dynamics": self.dynamics.key(),
            "grid": grid.key(),
            "horizon": self.horizon,
            "order": self.order,
            "rk": self.rk,
            "cfl": self.cfl,
            "thickness": float(maze.thickness),
            "walls": np.round(np.asarray(maze.walls, float), 6).tolist(),
            "version": 1,
        }

    def value_function(self, maze, grid: Grid) -> np.ndarray:
        """The avoid value of the maze's walls on ``grid`` (from the cache when there)."""

        def solve():
            return solve_brt(
                grid,
                self.dynamics,
                wall_target(grid, maze),
                self.horizon,
                order=self.order,
                rk=self.rk,
                cfl=self.cfl,
                backend=self.backend,
                threads=self.threads,
            )[0]

        V, seconds = load_or_solve(self.cache or None, self.spec(maze, grid), grid.shape, solve, self._counts)
        if seconds is not None:
            self.solve_seconds = seconds
        return V

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        space = self.action_space
        assert space is not None  # check_spaces refused anything but the maze car's GuardianActionSpace
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        maze = priv["maze"]
        if np.asarray(maze.walls).shape[0] == 0:
            raise ValueError(f"guardian {self.name!r} (maze) needs a maze with walls, got none")
        state = np.asarray(priv["state"], float)
        if "speed" not in priv:
            raise ValueError(
                f"guardian {self.name!r} (maze) needs the car's speed in the env's privileged data "
                f"(keys: {sorted(priv)})"
            )
        self.speed = finite("privileged speed", priv["speed"], 0.0, lo_open=True)
        self.u_max = float(space.control_high[0])
        env = self.disturbance == "env"
        d_max = env_disturbance_bound(priv.get("disturbances", ())) if env else float(self.disturbance)
        self.dynamics = Dubins4DHJ(u1_max=self.u_max, u2_max=0.0, v_min=self.speed, v_max=self.speed, d_max=d_max)
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
        self._maze_geom = (
            np.ascontiguousarray(np.asarray(maze.walls, float)),
            float(maze.half),
            float(maze.width),
            float(maze.height),
        )
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
        self._pose = None
        if not self.finite_state(s):
            u = self._safe(observation) if self._safe is not None else self.action_space.control_high
            return self.action_space.active(u)
        psi = (s[2] + math.pi) % (2 * math.pi) - math.pi
        if not self.grid.contains(np.array([s[0], s[1], psi, self.speed])):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        self._pose = (float(s[0]), float(s[1]), float(psi))
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
        :mod:`rmm_guardians.hj.maze_lookahead`) and its end pose."""
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
        path_clearances(
            x, y, psi, self.speed, man, min(SAMPLE_DT, duration), near, half, width, height, COEF, clear, ends
        )
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

    def signals(self) -> dict[str, float]:
        """``value``: the avoid value ``V`` of the walls (px, the maze's unit) at the pose the last decision read
        (``nan`` off the grid, for a non-finite state, or before a decision); ``value_threshold``:
        under ``rule="distance"`` the value at or below which it takes control, under the
        look-ahead rule the value above which it does not look ahead (below it the look-ahead
        decides, so a value under this line is not by itself a takeover).  Interpolated here
        from the stored pose: never changes a decision."""
        line = self.threshold() if self.rule == "distance" else self.band
        if self._pose is None or self.V is None:
            return {"value": math.nan, "value_threshold": float(line) if self.V is not None else math.nan}
        return {"value": float(self.evaluate(self._pose)[0]), "value_threshold": float(line)}

    def alarm(self) -> tuple[float, float]:
        """``(-value, -value_threshold)`` of :meth:`signals`: up when the value is below its line."""
        s = self.signals()
        return -s["value"], -s["value_threshold"]


def _turn_rate(info, key: str) -> float:
    """The turn rate ``info[key]`` (the env's documented ``nominal_control``), refused (naming
    it) when missing or not one finite number."""
    if not isinstance(info, dict) or key not in info:
        raise ValueError(
            f"guardian 'hj' (maze, rule='lookahead') needs info[{key!r}] from the env "
            f"(got keys {sorted(info) if isinstance(info, dict) else type(info).__name__})"
        )
    u = np.asarray(info[key], float).reshape(-1)
    if u.shape != (1,) or not math.isfinite(float(u[0])):
        raise ValueError(f"info[{key!r}] must be one finite turn rate, got {info[key]!r}")
    return float(u[0])
