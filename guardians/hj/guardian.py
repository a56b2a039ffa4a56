"""The grid Hamilton-Jacobi reachability guardians: ``hj`` (the default) and ``hj-paper``.

Both read **privileged** data (the obstacles at reset, the true state and the sim time every
step).  At reset the guardian solves (or loads from the cache) the backward reachable tube of
the episode's obstacles for the Dubins4D dynamics over ``horizon`` seconds; each step it takes
control, with the value's bang-bang optimal control, when ``V`` is at or below what the car
can lose before its decision acts: ``margin + v T + u2_max T^2 / 2`` for ``hj``
(``T = (1 + delay) * lap``), ``0`` for ``hj-paper``.  The name ``hj`` also serves the maze car
and the quadrotor (dispatched on the action space's dynamics).

Offers :class:`HJGuardian`, :class:`HJPaperGuardian`, :func:`default_grid` and
:func:`obstacle_target`; the settings and presets are in :mod:`rmm_guardians.hj.settings`.  The
rule and every argument: :class:`HJGuardian`; why: docs/decisions/0011-hj-rule.md, 0010 (scheme).
"""

from __future__ import annotations

import math

import numpy as np

from rmm_guardians._checks import settings_signature
from rmm_guardians.dispatch import DynamicsDispatch
from rmm_guardians.hj.cache import ValueCache, load_or_solve
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.grid import Grid, central_gradient
from rmm_guardians.hj.settings import HJ_PRESETS, HJSettings, env_disturbance_bound
from rmm_guardians.hj.solver import THREADS_VARIABLE, default_threads, select_backend, solve_brt  # noqa: F401
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import dubins4d_only

__all__ = ["HJGuardian", "HJPaperGuardian", "default_grid", "default_threads", "obstacle_target"]


def default_grid(n=(64, 64, 32, 32), half_width: float = 15.0, v_max: float = 4.0) -> Grid:
    return Grid([-half_width, -half_width, -np.pi, 0.0], [half_width, half_width, np.pi, v_max], n, periodic=[2])


def obstacle_target(grid: Grid, obstacles: np.ndarray) -> np.ndarray:
    """Signed distance to the union of circles, broadcast over heading and speed (float32)."""
    X, Y = grid.coord(0), grid.coord(1)
    dist = np.full((grid.n[0], grid.n[1], 1, 1), np.inf)
    for ox, oy, r in obstacles:
        dist = np.minimum(dist, np.sqrt((X - ox) ** 2 + (Y - oy) ** 2) - r)
    return np.broadcast_to(dist, grid.shape).astype(np.float32)


class HJGuardian(DynamicsDispatch, PrivilegedGuardian):
    """Grid HJ reachability guardian for Dubins4D (``hj``); the maze car and the quadrotor are
    handed to the method's parts (:mod:`rmm_guardians.parts`: :class:`~rmm_guardians.hj.maze.MazeHJGuardian`,
    :class:`~rmm_guardians.hj.quadrotor.QuadrotorHJGuardian`) by the action space's dynamics.

    **Value**: at reset, the backward reachable tube of all the episode's obstacles over
    ``horizon`` (4 s) on the default grid ``x, y in [-15, 15]`` (64 points each), heading periodic
    (32), speed ``[0, 4]`` (32; the paper's grid, although the env holds ``v <= 2``).  The target
    is the exact signed distance to the union of the circles, so ``V`` is in metres; its gradient
    is precomputed (central differences).  The reset time is the episode's ``precompute_time``,
    not charged to the episode's clock.

    **Rule** (``rule="distance"``): take control when ``V <= margin + v T + u2_max T^2 / 2``,
    ``T = (1 + delay) * lap``, ``lap`` measured from the simulated times (``lap=None``; 0.1 s
    before the first), with the bang-bang maximiser of ``grad V . f`` (``u1 = +-u1_max`` by the
    sign of ``dV/dtheta``, ``u2 = +-u2_max`` by that of ``dV/dv``).  ``rule="gradient"``: act when
    ``V <= margin + T rho + T^2 kappa / 2``, ``rho = max(0, -min_u grad V . f)``,
    ``kappa = |grad_xy V| sqrt((v u1_max)^2 + u2_max^2)``; ``rule="value"``: when ``V <= margin``.
    Below one speed cell the gradient is read one speed cell up (``standstill_lookup``, counted
    in ``standstill_lookups``): at standstill ``dV/dtheta = 0`` and the control would only brake.

    **Arguments** (:class:`~rmm_guardians.hj.settings.HJSettings`): ``grid`` or ``grid_n``,
    ``horizon``, ``order`` (1 upwind, 2 ENO2), ``rk`` (TVD RK order), ``cfl`` (0.8), ``rule``,
    ``margin`` (m; ``None``: half a position cell, 0.238 m on the default grid), ``delay`` (laps;
    0 in the blocking ``Dubins4DGuarded-v0``), ``lap``, ``disturbance`` (0, as the paper ran;
    ``"env"``: the bound of the run's own ``dyn-rate`` disturbance on x and y, read at every
    reset, 0 when it has none),
    ``cache_dir`` (``None``: ``$RMM_HJ_CACHE`` if set, else ``~/.cache/rmm-envs/hj``), ``cache``,
    ``cache_max_files`` (64 files of 17 MB), ``backend`` (``"auto"``: the compiled kernel;
    ``"numpy"``/``"numba"``: both give the same value to float32 rounding and share cache
    entries), ``threads`` (``None``: ``$RMM_HJ_THREADS``, else numba's; never changes the value),
    ``mode="reach_avoid"`` (also the goal's reach-avoid value over ``ra_horizon``, 10 s: while
    ``-ra_margin <= V_ra <= 0`` it steers to keep it; a second, 2.5x longer solve), ``maze`` and
    ``quadrotor`` (the other systems' arguments; ``False`` refuses them; ``cache_dir``, ``cache``,
    ``cache_max_files``, ``backend``, ``threads``, ``delay``, ``lap`` and, when set, ``disturbance``
    are shared: the maze car's part models it, the quadrotor's refuses it).

    It needs privileged data and an action space with the two Dubins4D controls, symmetric about 0
    (the dynamics' bounds are read from it and enter the cache key).  A state outside the grid's
    position/speed box leaves control to the driver (``outside_grid``); a state with NaN brakes at
    maximum (``nan_states``); an obstacle centre off the grid is refused at reset."""

    name = "hj"
    method = "hj"  #: its parts serve the other dynamics (rmm_guardians.parts: the maze car, the quadrotor)
    own_check = staticmethod(dubins4d_only)

    preset = "hj"  #: the HJSettings preset the keyword arguments change

    def __init__(self, settings: HJSettings | None = None, **options) -> None:
        """``settings`` (default: the class's :attr:`preset`) with ``options``, any of
        :class:`~rmm_guardians.hj.settings.HJSettings`' fields, changed."""
        super().__init__()
        s = self.settings = (settings if settings is not None else HJ_PRESETS[self.preset]).replace(**options)
        shared = {
            "cache_dir": s.cache_dir,
            "cache": s.cache,
            "cache_max_files": s.cache_max_files,
            "backend": s.backend,
            "threads": s.threads,
            "delay": s.delay,
            "lap": s.lap,
        }
        if s.disturbance != 0.0:  # shared when set: the maze car's part models it, the quadrotor's refuses it
            shared["disturbance"] = s.disturbance
        self._init_parts(s, shared)
        self.standstill_lookup, self.horizon, self.mode, self.rule = s.standstill_lookup, s.horizon, s.mode, s.rule
        self.order, self.rk, self.cfl = s.order, s.rk, s.cfl
        self.threads = default_threads() if s.threads is None else s.threads
        self.ra_horizon, self.ra_margin, self.delay, self.lap = s.ra_horizon, s.ra_margin, s.delay, s.lap
        self.grid = s.grid or (default_grid(s.grid_n) if s.grid_n is not None else default_grid())
        # default: half a position cell, the most multilinear interpolation can over-state V
        # at a kink of a function that is 1-Lipschitz in position
        self.margin = 0.5 * float(max(self.grid.dx[0], self.grid.dx[1])) if s.margin is None else s.margin
        # the Dubins4D system's bounds; reset replaces the control bounds by the action space's
        self._disturbance_from_env = s.disturbance == "env"
        self.dynamics = Dubins4DHJ(d_max=0.0 if self._disturbance_from_env else float(s.disturbance))
        self.backend = s.backend
        select_backend(self.grid, self.dynamics, self.order, s.backend)  # a bad choice fails here, not at reset
        self.cache = ValueCache(s.cache_dir, s.cache_max_files) if s.cache else None
        self._counts = {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}
        self.solve_seconds = 0.0
        self.V: np.ndarray | None = None
        self._value = self._value_threshold = math.nan  # the last decision's (signals())

    def spec(self, obstacles, goal=None) -> dict:
        spec = {
            "dynamics": self.dynamics.key(),
            "grid": self.grid.key(),
            "horizon": self.horizon,
            "order": self.order,
            "rk": self.rk,
            "cfl": self.cfl,
            "obstacles": np.round(np.asarray(obstacles, float), 9).tolist(),
            "version": 1,
        }
        if goal is not None:  # the reach-avoid value: goal and its own horizon
            spec |= {
                "mode": "reach_avoid",
                "goal": np.round(np.asarray(goal, float), 9).tolist(),
                "horizon": self.ra_horizon,
            }
        return spec

    def value_function(self, obstacles, goal=None) -> np.ndarray:
        """The avoid value of the obstacles (``goal=None``) or the reach-avoid value of the goal."""
        obstacles = np.asarray(obstacles, float).reshape(-1, 3)
        for ox, oy, _r in obstacles:
            if not (self.grid.lo[0] <= ox <= self.grid.hi[0] and self.grid.lo[1] <= oy <= self.grid.hi[1]):
                raise ValueError(
                    f"obstacle centred at ({ox:.2f}, {oy:.2f}) lies outside the HJ grid "
                    f"[{self.grid.lo[0]}, {self.grid.hi[0]}] x [{self.grid.lo[1]}, {self.grid.hi[1]}]"
                )

        def solve():
            if goal is None:
                return solve_brt(
                    self.grid,
                    self.dynamics,
                    obstacle_target(self.grid, obstacles),
                    self.horizon,
                    order=self.order,
                    rk=self.rk,
                    cfl=self.cfl,
                    backend=self.backend,
                    threads=self.threads,
                )[0]
            return solve_brt(
                self.grid,
                self.dynamics,
                obstacle_target(self.grid, np.asarray(goal, float).reshape(1, 3)),
                self.ra_horizon,
                order=self.order,
                rk=self.rk,
                cfl=self.cfl,
                constraint=obstacle_target(self.grid, obstacles),
                backend=self.backend,
                threads=self.threads,
            )[0]

        V, seconds = load_or_solve(self.cache or None, self.spec(obstacles, goal), self.grid.shape, solve, self._counts)
        if seconds is not None:
            self.solve_seconds = seconds
        return V

    def reset(self, **kwargs) -> None:
        if self._dispatch_reset(kwargs):
            return
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        space = self.require_action_space(controls=2)
        d = self.dynamics
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        d_max = env_disturbance_bound(priv.get("disturbances", ())) if self._disturbance_from_env else d.d_max
        try:
            dyn = Dubins4DHJ.from_bounds(space.control_low, space.control_high, d.v_min, d.v_max, d_max)
        except ValueError as e:
            raise ValueError(f"guardian {self.name!r}: {e}") from None
        if dyn != d:
            self.dynamics = dyn
        self._counts = {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}
        self.V = self.value_function(priv["obstacles"])
        self.grads = central_gradient(self.V, self.grid)
        self._arrays = [self.V, *self.grads]
        self._interp = self.grid.interpolator(self._arrays)
        self._ra_arrays = None
        self._ra_interp = None
        self._value = self._value_threshold = math.nan
        self.start_laps()
        if self.mode == "reach_avoid":
            V_ra = self.value_function(priv["obstacles"], goal=priv["goal"])
            self._ra_arrays = [V_ra, *central_gradient(V_ra, self.grid)]
            self._ra_interp = self.grid.interpolator(self._ra_arrays)

    def evaluate(self, state) -> np.ndarray:
        """``(V, dV/dx, dV/dy, dV/dtheta, dV/dv)`` at ``state``."""
        return self._interp(np.asarray(state, float))

    def decrease_rate(self, state, grad) -> float:
        """How fast ``V`` can fall at ``state`` under the worst held control (first order, ``>= 0``)."""
        d = self.dynamics
        _, _, th, v = state
        vx, vy, vth, vv = grad
        drift = v * (vx * math.cos(th) + vy * math.sin(th))
        # the worst u2 pushes v against the sign of dV/dv, unless the clamp stops it there
        speed = abs(vv) if d.v_min < v < d.v_max else (max(0.0, vv) if v >= d.v_max else max(0.0, -vv))
        return max(0.0, -drift + d.u1_max * abs(vth) + d.u2_max * speed)

    def threshold(self, state, grad) -> float:
        """The value at or below which the guardian takes control at ``state``."""
        if self.rule == "value":
            return self.margin
        T = (1 + self.delay) * self.current_lap()  # the time one decision commits
        v, a = float(state[3]), self.dynamics.u2_max
        if self.rule == "distance":  # V is 1-Lipschitz in position: at most the path length
            return self.margin + v * T + 0.5 * a * T * T
        # "gradient": first order along the worst held control, plus the path's bending
        bend = math.hypot(grad[0], grad[1]) * math.hypot(v * self.dynamics.u1_max, a)
        return self.margin + T * self.decrease_rate(state, grad) + 0.5 * T * T * bend

    def act(self, observation, info=None):
        if self.delegate is not None:
            return self.delegate.act(observation, info)
        s = self._state_and_lap()
        return self._decide(s)

    def _decide(self, s):
        self._value = self._value_threshold = math.nan  # what signals() reports of this decision
        if not self.finite_state(s):
            return self.action_space.active((0.0, -self.dynamics.u2_max))
        if not self.grid.contains(s):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        vals = self.evaluate(s).tolist()  # Python floats: the rule below is scalar arithmetic
        self._value, self._value_threshold = vals[0], self.threshold(s.tolist(), vals[1:])
        if self._value <= self._value_threshold:  # safety first: the avoid value
            grad = vals[1:]
            cell = self.grid.dx[3]
            if self.standstill_lookup and s[3] < cell:
                # at standstill the heading does not change V (dV/dtheta = 0): the control is
                # read one speed cell up, where the value says which way to turn and whether
                # to move off (otherwise a car stopped within the margin is held there forever)
                grad = self.evaluate(np.array([s[0], s[1], s[2], cell]))[1:].tolist()
                self._counts["standstill_lookups"] = self._counts.get("standstill_lookups", 0) + 1
            return self.action_space.active(self.dynamics.optimal_control(s, grad))
        if self._ra_interp is not None:
            ra = self._ra_interp(s)
            if -self.ra_margin <= ra[0] <= 0.0:  # at the edge of the reach-avoid set: steer to the goal
                self._counts["reach_avoid_steps"] = self._counts.get("reach_avoid_steps", 0) + 1
                return self.action_space.active(self.dynamics.optimal_control(s, ra[1:], control="min"))
        return self.action_space.inactive()

    def stats(self) -> dict:
        if self.delegate is not None:
            return self.delegate.stats()
        return dict(self._counts, solve_seconds=self.solve_seconds)

    def signals(self) -> dict[str, float]:
        """``value``: the avoid value ``V`` (m, interpolated) at the state the last decision read;
        ``value_threshold``: the value at or below which it takes control there; both ``nan``
        when the state was off the grid or not finite (or before a decision).  On the maze car
        and the quadrotor, the same two names from their guardian (:class:`MazeHJGuardian`,
        :class:`QuadrotorHJGuardian`)."""
        if self.delegate is not None:
            return self.delegate.signals()
        return {"value": float(self._value), "value_threshold": float(self._value_threshold)}

    def alarm(self) -> tuple[float, float] | None:
        """``(-value, -value_threshold)`` of :meth:`signals`: up when the avoid value at the state
        the last decision read is below its line (on the maze car under the look-ahead rule, the
        line below which it looks ahead)."""
        if self.delegate is not None:
            return self.delegate.alarm()
        return -float(self._value), -float(self._value_threshold)


# a function's attributes live in its __dict__ (the type checker knows no __signature__ on a method)
HJGuardian.__init__.__dict__["__signature__"] = settings_signature(HJSettings, HJ_PRESETS["hj"])


class HJPaperGuardian(HJGuardian):
    """The paper's HJ guardian (``hj-paper``): first-order scheme with RK2, take control when
    ``V <= 0`` with the bang-bang optimal control, no allowance for the action latency (the
    ``hj-paper`` preset)."""

    name = "hj-paper"
    preset = "hj-paper"
