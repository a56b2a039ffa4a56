"""The grid Hamilton-Jacobi reachability guardians: ``hj`` (the default) and ``hj-paper``.

Both use **privileged** information: the obstacles at reset, the true state and the sim time
every step.

## The value function

At reset the guardian computes (or loads from the cache) the backward reachable tube of **all**
the episode's obstacles for the Dubins4D dynamics over the ``horizon`` (4 s, the paper's), on
the default grid ``x, y in [-15, 15]`` (64 points each), heading periodic with period 2 pi (32
points), speed ``v in [0, 4]`` (32 points; the paper's grid, although the environment holds
``v <= 2``).  The target is the exact signed distance to the union of the circles, so ``V`` is
in metres: the closest the car can be kept to an obstacle over the horizon.  It then
precomputes the value's gradient (central differences).  That reset time is reported as the
episode's ``precompute_time`` and, as in the paper's reported HJ row, is not charged to the
episode's clock unless asked.

Scheme (``order``, ``rk``): ``hj`` uses ENO2 differences with third-order TVD Runge-Kutta
(``order=2, rk=3``).  The first-order scheme (``order=1, rk=2``, ``hj-paper``'s) is diffusive:
it under-estimates the unsafe set.  On the circle test in ``tests/test_hj.py`` it marks 3.75% of
the nodes unsafe against 4.3% for the converged answer, while ENO2/RK3 on the same grid gets
within 0.06 points of it and agrees on the sign at 99.9% of nodes.  The compiled ENO2 solve
costs about 3x the first-order one.  The cache key includes ``order``, ``rk`` and ``cfl``, so
values of different schemes never mix.

## The rule of ``hj``: act in time for the one-lap latency

In the parallel-autonomy loop an action takes effect one lap late.  The action computed from
the state ``s_k`` (returned by step ``k``) is applied from ``s_{k+1}`` on, and the lap from
``s_k`` to ``s_{k+1}`` runs under the *previous* action.  A lap lasts
``base_step + time_accel * thinking time`` (0.11 s under ``--clock fixed:1``).  The guardian
measures it as the difference of successive sim times (``lap=None``).  Before it has seen one
lap it assumes 0.1 s, the environment's default base step.

So a decision at ``s_k`` commits ``T = (1 + delay) * lap`` seconds (``delay=1``: the pending
lap and the lap the decision governs; use ``delay=0`` in the blocking ``Dubins4DCirclesGuarded-v0``,
where an action acts at once).  Staying passive is safe only if, whatever the driver does in
that time, the guardian can still take over: the value at the end of ``T`` must still be
positive.  The dynamics are invariant under translation and the target is a distance, so
``V`` is 1-Lipschitz in position: moving the car by ``d`` metres lowers ``V`` by at most ``d``.
In ``T`` seconds, starting at speed ``v``, the car covers at most ``v T + u2_max T^2 / 2``
metres.  ``hj`` (``rule="distance"``) therefore takes control when

    V(s) <= margin + v T + u2_max T^2 / 2

which is 0.24 + 0.44 + 0.01 = 0.69 m at 2 m/s with 0.11 s laps.  ``margin`` is the
numerical error of the value as the guardian sees it.  ``V`` is interpolated multilinearly
between grid nodes, and at a kink of a function with slopes of at most 1 that over-states
the value by up to half a cell.  So the default is half a position cell, ``dx / 2`` (0.238 m
on the default grid), and it shrinks with a finer grid.  ``margin`` is also the knob of the
sensitivity study.

What the distance bound leaves out: the heading and speed the driver changes in ``T``
(at most 0.055 rad and 0.11 m/s) also move ``V``.  ``rule="gradient"`` bounds them to first
order with the value's gradient.  It acts when ``V <= margin + T rho(s) + T^2 kappa(s) / 2``,
where ``rho = max(0, -min_u grad V . f)`` is the worst rate of decrease and
``kappa = |grad_xy V| sqrt((v u1_max)^2 + u2_max^2)`` bounds how much the path bends.  It
counts the driver's worst acceleration even from standstill, so it keeps a stopped car facing
an obstacle stopped.  We compared the two on the first 52 episodes of seed 0 (fixed 1 ms
clock, before the standstill rule below): both collided in 7.7% of them, "gradient" with
28.8% timeouts against 15.4%.  So "distance" is the default, chosen on that comparison.

When acting, the guardian applies the value function's optimal control, the bang-bang
maximiser of ``grad V . f``: ``u1 = +-0.25`` by the sign of ``dV/dtheta``, ``u2 = +-0.5`` by
the sign of ``dV/dv``.  One degenerate case: at standstill the heading does not change ``V``
(``dV/dtheta = 0``).  The bang-bang control then only brakes, and a car stopped within the
margin of an obstacle would be held there until the episode times out.  Below one speed cell
(0.13 m/s) the guardian therefore reads the gradient one speed cell up, where the value says
which way to turn and whether to move off (``standstill_lookup=True``; counted in
``stats()["standstill_lookups"]``; ``hj-paper`` does not do this).

## ``hj-paper``: the paper's rule

``order=1, rk=2``, ``rule="value"``, ``margin=0``: take control when ``V <= 0`` with the same
bang-bang control and no allowance for the latency.  This is what ``hj`` did before the rule
above.

## Arguments

``grid`` (a :class:`Grid`) or ``grid_n`` (points per axis of the default box), ``horizon`` (4
s), ``order`` (1: upwind, 2: ENO2), ``rk`` (TVD RK order), ``cfl`` (0.8), ``rule``
(``"distance"``, ``"gradient"`` or ``"value"``: act when ``V <= margin``), ``margin`` (m;
``None``: half a position cell), ``delay`` (laps), ``lap`` (s, ``None``: measured),
``disturbance`` (bound on the position-rate disturbance, 0 as the paper ran),
``cache_dir`` (``None``: ``$RMM_HJ_CACHE`` if set, else ``~/.cache/rmm-envs/hj``; read in
:func:`guardians.hj.cache.default_cache_dir`), ``cache`` (False: always solve),
``cache_max_files`` (64 files of 17 MB on the default grid), ``backend`` (``"auto"``: the
compiled numba kernel, which covers both orders; or ``"numpy"``/``"numba"``; both give the
same value to float32 rounding, so they share cache entries), ``threads`` (threads of the
compiled solve; ``None``: ``$RMM_HJ_THREADS`` if set, read in :func:`default_threads`, else
numba's default, the core count; ``rmm-bench`` passes 1 when several workers share the
machine; the value does not depend on it).  A non-finite or out-of-range value is refused at
construction with a message naming it.

What it needs from the env, checked at ``reset``: privileged data (obstacles, state, sim
time) and an action space (:class:`rmm_envs.autonomy.GuardianActionSpace`) with the two
Dubins4D controls, symmetric about 0.  Every action is built through that space, and the
control bounds of the HJ dynamics are read from it (speed bounds: the Dubins4D system's);
they enter the value cache's key, so values for other bounds never mix.

Goal-aware variant (``mode="reach_avoid"``): it also solves the reach-avoid value of the goal
over ``ra_horizon`` (10 s; the obstacles as a state constraint).  ``V_ra <= 0`` marks states
that can reach the goal within that time without a collision.  The avoid rule above still
comes first; otherwise, when the state is at the edge of the reach-avoid set
(``-ra_margin <= V_ra <= 0``), the guardian steers with the reach-avoid optimal control
(which minimises ``V_ra``) so as not to lose it.  It costs a second, 2.5x longer solve
(cached likewise).  First-order Lax-Friedrichs is diffusive over a long reach horizon: on
coarse grids the reach-avoid set is under-estimated (conservative).  For a state 3 m behind
the goal's centre at 1 m/s, with a 4 s horizon, the first-order value (about -1 exactly) is
-0.04, -0.39 and -0.54 on 33, 65 and 97 points per position axis.

## The maze car and the quadrotor

``hj`` also serves the maze car (``Dubins3DMazeParallel-v0``): given an action space with the
maze car's one control (``turnrate_ctrl``), it hands the episode to
:class:`guardians.hj.maze.MazeHJGuardian` (a 3-D value over the maze's walls, same rule; its
module docstring has its defaults).  ``maze`` (a dict) sets that guardian's own arguments;
``cache_dir``, ``cache``, ``cache_max_files``, ``backend``, ``threads``, ``delay`` and ``lap``
are shared.  ``maze=False`` refuses maze envs (``hj-paper`` does: the paper's rule is for
Dubins4D only).  Likewise the quadrotor's action space (four velocity commands) goes to
:class:`guardians.hj.quadrotor.QuadrotorHJGuardian` (``quadrotor``, a dict; ``False`` refuses).

Explicit edge cases: a state outside the grid's position/speed box has no value: the guardian
leaves control to the driver and counts it (``stats()["outside_grid"]``); a state with NaN
brakes at maximum and is counted (``nan_states``); an obstacle whose centre lies outside the
grid is refused at reset (``ValueError``).  The original used only the first obstacle, padded
its periodic axis to a period of 2 pi + 0.2 and stopped acting once the heading wound past
about +-pi; none of that applies here.
"""

from __future__ import annotations

import math

import numpy as np

from guardians._checks import settings_signature
from guardians.privileged import PrivilegedGuardian
from guardians.dispatch import SystemDispatch, delegate_arguments
from guardians.hj.cache import ValueCache, load_or_solve
from guardians.hj.dynamics import Dubins4DHJ
from guardians.hj.grid import Grid
from guardians.hj.grid import central_gradient
from guardians.hj.maze import MazeHJGuardian
from guardians.hj.quadrotor import QuadrotorHJGuardian
from guardians.hj.settings import HJ_PRESETS, HJSettings
from guardians.hj.solver import THREADS_VARIABLE, default_threads, select_backend, solve_brt  # noqa: F401
from rmm_envs.systems import dubins3d, quadrotor_control

__all__ = ["HJGuardian", "HJPaperGuardian", "default_grid", "default_threads", "obstacle_target"]

def default_grid(n=(64, 64, 32, 32), half_width: float = 15.0, v_max: float = 4.0) -> Grid:
    return Grid([-half_width, -half_width, -np.pi, 0.0], [half_width, half_width, np.pi, v_max], n, periodic=[2])


def obstacle_target(grid: Grid, obstacles: np.ndarray) -> np.ndarray:
    """Signed distance to the union of circles, broadcast over heading and speed (float32)."""
    X, Y = grid.coord(0), grid.coord(1)
    l = np.full((grid.n[0], grid.n[1], 1, 1), np.inf)
    for ox, oy, r in obstacles:
        l = np.minimum(l, np.sqrt((X - ox) ** 2 + (Y - oy) ** 2) - r)
    return np.broadcast_to(l, grid.shape).astype(np.float32)


class HJGuardian(SystemDispatch, PrivilegedGuardian):
    name = "hj"
    others = {dubins3d.KIND: MazeHJGuardian, quadrotor_control.KIND: QuadrotorHJGuardian}

    preset = "hj"  #: the HJSettings preset the keyword arguments change

    def __init__(self, settings: HJSettings | None = None, **options) -> None:
        """``settings`` (default: the class's :attr:`preset`) with ``options``, any of
        :class:`~guardians.hj.settings.HJSettings`' fields, changed."""
        super().__init__()
        s = self.settings = (settings if settings is not None else HJ_PRESETS[self.preset]).replace(**options)
        shared = {"cache_dir": s.cache_dir, "cache": s.cache, "cache_max_files": s.cache_max_files, "backend": s.backend,
                  "threads": s.threads, "delay": s.delay, "lap": s.lap}
        self._system_args = {dubins3d.KIND: delegate_arguments(MazeHJGuardian, "maze", s.maze, shared),
                             quadrotor_control.KIND: delegate_arguments(QuadrotorHJGuardian, "quadrotor", s.quadrotor, shared)}
        self.standstill_lookup, self.horizon, self.mode, self.rule = s.standstill_lookup, s.horizon, s.mode, s.rule
        self.order, self.rk, self.cfl = s.order, s.rk, s.cfl
        self.threads = default_threads() if s.threads is None else s.threads
        self.ra_horizon, self.ra_margin, self.delay, self.lap = s.ra_horizon, s.ra_margin, s.delay, s.lap
        self.grid = s.grid or (default_grid(s.grid_n) if s.grid_n is not None else default_grid())
        # default: half a position cell, the most multilinear interpolation can over-state V
        # at a kink of a function that is 1-Lipschitz in position
        self.margin = 0.5 * float(max(self.grid.dx[0], self.grid.dx[1])) if s.margin is None else s.margin
        # the Dubins4D system's bounds; reset replaces the control bounds by the action space's
        self.dynamics = Dubins4DHJ(d_max=s.disturbance)
        self.backend = s.backend
        select_backend(self.grid, self.dynamics, self.order, s.backend)  # a bad choice fails here, not at reset
        self.cache = ValueCache(s.cache_dir, s.cache_max_files) if s.cache else None
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

        def solve():
            if goal is None:
                return solve_brt(self.grid, self.dynamics, obstacle_target(self.grid, obstacles), self.horizon,
                                 order=self.order, rk=self.rk, cfl=self.cfl, backend=self.backend, threads=self.threads)[0]
            return solve_brt(self.grid, self.dynamics, obstacle_target(self.grid, np.asarray(goal, float).reshape(1, 3)),
                             self.ra_horizon, order=self.order, rk=self.rk, cfl=self.cfl,
                             constraint=obstacle_target(self.grid, obstacles), backend=self.backend,
                             threads=self.threads)[0]

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
        try:
            dyn = Dubins4DHJ.from_bounds(space.control_low, space.control_high, d.v_min, d.v_max, d.d_max)
        except ValueError as e:
            raise ValueError(f"guardian {self.name!r}: {e}") from None
        if dyn != d:
            self.dynamics = dyn
        self._counts = {"outside_grid": 0, "nan_states": 0, "cache_hits": 0, "solves": 0}
        priv = self._privileged()
        self.V = self.value_function(priv["obstacles"])
        self.grads = central_gradient(self.V, self.grid)
        self._arrays = [self.V, *self.grads]
        self._interp = self.grid.interpolator(self._arrays)
        self._ra_arrays = None
        self._ra_interp = None
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
        if not self.finite_state(s):
            return self.action_space.active((0.0, -self.dynamics.u2_max))
        if not self.grid.contains(s):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        vals = self.evaluate(s).tolist()  # Python floats: the rule below is scalar arithmetic
        if vals[0] <= self.threshold(s.tolist(), vals[1:]):  # safety first: the avoid value
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


HJGuardian.__init__.__signature__ = settings_signature(HJSettings, HJ_PRESETS["hj"])


class HJPaperGuardian(HJGuardian):
    """The paper's HJ guardian (``hj-paper``): first-order scheme with RK2, take control when
    ``V <= 0`` with the bang-bang optimal control, no allowance for the action latency (the
    ``hj-paper`` preset)."""

    name = "hj-paper"
    preset = "hj-paper"
