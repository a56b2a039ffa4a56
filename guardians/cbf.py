"""High-order control barrier function (HOCBF) guardians, solved with OSQP: ``cbf`` and ``cbf-paper``.

Both use **privileged** information: the true state, the obstacles, the goal and the simulated
time (from the env's documented ``privileged()`` accessor).  After Xiao & Belta's HOCBFs, as in
the paper.

The QP (shared by both)
-----------------------
For each circular obstacle ``i`` a relative-degree-2 barrier with inflation ``k``::

    b_i = (x - x_i)^2 + (y - y_i)^2 - (k r_i)^2
    Lf b = 2 v ((x - x_i) cos th + (y - y_i) sin th),   Lf^2 b = 2 v^2
    LgLf b = [2 v ((y - y_i) cos th - (x - x_i) sin th),  2 ((x - x_i) cos th + (y - y_i) sin th)]
    Lf^2 b + LgLf b . u + p1 Lf b + p2 (Lf b + p1 b) >= 0        (linear class-K, p1, p2)

The QP over ``z = (u1, u2, d_th, d_v)``::

    minimise u1^2 + u2^2 + p_th d_th^2 + p_v d_v^2
    s.t. the barrier rows above (hard), the speed barriers and control box (merged into one
    row on u2, as in the driver), the heading CLF (as the driver's) and a speed CLF toward
    v_d = min((d/2)^2, d/2) with V_v = (v - v_d)^2.

Defaults shared by both guardians, and why:

* ``p1 = 0.7535, p2 = 0.6664``: the paper's class-K gains.
* ``inflation = 1.05``: the paper's 5% obstacle inflation (a margin of 0.1-0.25 m for radii of
  2-5 m, about one step of travel at full speed).
* ``gamma_vmin = gamma_vmax = lambda_theta = lambda_v = p_theta = p_v = 1``: the paper's (the
  same values the env's driver uses).
* control box ``|u1| <= 0.25``, ``|u2| <= 0.5``, speeds ``[0, 2]``: the env's.
* The original wrote the speed CLF as ``(v - v_d) * 82`` (a typo for the square); we use the
  square.  The original also braked fully whenever ``v < 0.05`` (so a stopped car never moved
  again); that is off (``low_speed_stop=True`` restores it).
* Intervention: the guardian takes control, applying the QP's ``(u1, u2)``, when a barrier
  row is active at the solution: ``|G_i z* - h_i| <= active_atol + active_rtol |h_i|``
  (``1e-3`` and ``0``: equality up to the solver's polished accuracy; the original used a loose
  0.1/0.1).  Otherwise the driver keeps control.  The rule is kept: a row that is not active
  at the CBF-CLF optimum is slack by more than ``1e-3``, and the one-step prediction below
  makes it hold for the state the decision is applied from.
* ``eps = 1e-6`` (OSQP's absolute/relative tolerance, solutions polished), ``max_obstacles = 64``
  (more is refused at reset: the QP is sized once per episode).

The problem is set up once per episode (fixed sparsity for the episode's obstacles) and each
step only updates values and bounds, then re-solves warm-started.  A state with NaN brakes at
maximum and is counted (``stats()["nan_states"]``).

``cbf-paper``: the paper's rule (:class:`CBFPaperGuardian`)
-----------------------------------------------------------
The QP is solved at the observed state; an infeasible or failed QP brakes at maximum with no
turn (``stats()["qp_fallbacks"]``).  This is the previous ``cbf`` exactly.  Its weakness: most
of its timeouts are a car that stopped for good.  Either it entered the inflation margin
facing the obstacle (the QP is infeasible there, it brakes, and a stopped car facing inward
can never satisfy the rows: at ``v = 0`` the turn rate drops out of them), or it stopped on
the margin with the goal behind the obstacle (the well-known CBF-QP deadlock: a stable
equilibrium with the barrier active and ``u = 0`` feasible but no motion).

``cbf``: the default (:class:`CBFGuardian`)
-------------------------------------------
Three changes, each for a stated reason:

1. **One-step latency** (``predict_latency=True``).  Under parallel autonomy the action
   returned for the state ``s_k`` is applied only from ``s_{k+1}``: during the lap from
   ``s_k`` to ``s_{k+1}`` the previous action (or the driver) still drives.  A lap lasts
   ``base_step + time_accel * thinking time`` (0.11 s under ``--clock fixed:1``), so at 2 m/s
   the car covers 0.22 m before the decision takes effect: as much as the whole 0.1-0.25 m
   inflation margin.  So the guardian solves its QP at the *predicted* state ``s_{k+1}``:
   the exact Dubins4D flow (``rmm_envs.systems``) from ``s_k`` under the control that will
   act during the lap.  If the guardian was in control that is its own last action, known
   exactly; if the driver was, the driver's control is unknown to the guardian and taken as
   zero, which bounds the prediction error by ``|u2|max lap^2 / 2`` = 3.0 mm in position and
   ``|u1|max lap`` = 0.0275 rad in heading at 0.11 s.  The lap is measured from the simulated
   times the env reports (the previous lap's length; ``lap_guess = 0.1`` s, the base step,
   before the first measurement).  Nothing here is tuned: it is the env's documented timing.
   Measured (256 episodes, fixed 1 ms clock, seed 0), its effect on outcomes is within the
   run-to-run noise: 6.6% collisions with and without it at ``k = 1.05`` (timeouts 3.1% against
   4.3%); nearly all remaining collisions start at speed too close to an obstacle to avoid, so
   latency is not what limits safety here.  It is kept because the decision then refers to
   the state it acts from, which is what the HOCBF condition assumes.
2. **Recovery instead of braking forever** (``recovery=True``).  The guardian enters
   recovery when the QP is infeasible or fails, or when it is deadlocked: a barrier row is
   active and the QP's control leaves the speed below ``v_stuck = 0.05`` m/s after the lap
   (5.5 mm of travel per 0.11-s lap: stopped for practical purposes; the same threshold the
   original used to call the car stopped).  Recovery is a backup manoeuvre about the obstacle
   ``i*`` whose row is hardest to satisfy (the smallest ``h_i + max_u LgLf b_i . u`` over the
   admissible controls).  With ``n`` the outward normal at the car and ``t`` one of the two
   tangents:

   * the tangent ``t``: while the car moves (``v > v_stuck``) the one with ``t . heading >= 0``
     (turning toward it turns the heading away from the centre, the sign that maximises
     ``d^2 b / dt^2`` through ``u1``); when stopped, the one on the goal's side.  The choice
     is kept for the whole recovery (it goes round one way, no dithering);
   * target heading: along ``t``, tilted 45 degrees outward (``t + n``) while inside the
     margin (``b < 0``), so that the car leaves it;
   * ``u1`` turns to the target heading at full rate, proportionally within one lap
     (``err / lap``) so that it does not overshoot while the command is held; while the
     heading points inward it always turns the way that rotates it away from the centre
     (never through it), so ``heading . n`` rises monotonically;
   * ``u2``: full braking while the heading points inward (``heading . n < 0``), which with
     the turn makes ``d^2 b/dt^2 = 2 v^2 + LgLf b . u > 0`` strictly; full acceleration (up to
     the speed barrier) once it does not, so that ``db/dt = 2 v |d| heading . n >= 0`` and the
     car moves off along the tangent; the acceleration is capped by every obstacle's barrier
     row (another obstacle may lie ahead).  A stopped car facing inward turns in place (at
     ``v = 0`` nothing else can help) until it faces out.
   * Blocked (stopped, on target, the cap forbids moving: the notch where two obstacles
     overlap), it goes round the other way; blocked again, it recovers from the obstacle that
     now blocks.

   Recovery ends when the car is outside every margin (all ``b_i >= 0``), its heading does
   not point into ``i*``, and the straight line to the goal clears the inflated ``i*`` (so
   the same deadlock cannot form again).  Each step spent recovering is counted in
   ``stats()["recoveries"]`` and each entry in ``stats()["recovery_entries"]``;
   ``qp_fallbacks`` still counts every QP that failed or was infeasible (recovery took over).
   A state with NaN still brakes and is counted as ``nan_states``.
3. **A margin that never swallows the goal** (``goal_aware_margin=True``).  The env only
   guarantees that the goal is not entirely inside an obstacle; with the 5% inflation it is
   entirely inside some obstacle's *margin* in about 4% of episodes (measured over 1,000
   generated scenes), and a margin-respecting CBF can then never reach it (most of the
   remaining timeouts).  So each obstacle's inflated radius is
   ``max(r, min(k r, (r + F) / 2))`` with ``F`` the goal point farthest from its centre: the
   margin covers at most half of the goal's protrusion beyond the obstacle, and is the full
   ``k r`` for every obstacle not near the goal.

Inflation ``k = 1.05`` is kept at the paper's value.  A sweep over ``k`` (256 episodes, fixed
1 ms clock, seed 0; success / collision / timeout %) puts it at the knee: 1.0: 87.5 / 9.8 /
2.7; 1.02: 89.5 / 7.0 / 3.5; 1.05: 90.2 / 6.6 / 3.1; 1.1: 89.1 / 6.2 / 4.7; 1.2: 86.7 / 6.2 /
7.0.  Without a margin the sampled (0.11-s, zero-order-hold) loop lets the car graze
obstacles; beyond 5% collisions no longer fall while the margin blocks more gaps and goals.

Bad arguments (non-finite or non-positive gains, ``inflation < 1``, empty control or speed
ranges, negative tolerances) are refused at construction with a message naming the value.
"""

from __future__ import annotations

import math

import numpy as np
import osqp
import scipy.sparse as sp

from guardians.base import Guardian, active_action, inactive_action
from rmm_envs.driver import desired_heading
from rmm_envs.systems.dubins4d import Dubins4D

__all__ = ["CBFGuardian", "CBFPaperGuardian"]


def _finite(name, value, positive=False, nonneg=False):
    try:
        f = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a finite number, got {value!r}") from None
    if not math.isfinite(f):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if positive and not f > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if nonneg and not f >= 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")
    return f


def _range(name, pair, allow_equal=False):
    try:
        lo, hi = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (min, max) pair of numbers, got {pair!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or not (lo < hi or (allow_equal and lo == hi)):
        raise ValueError(f"{name} must be a finite (min, max) with min < max, got {pair!r}")
    return lo, hi


class CBFGuardian(Guardian):
    """HOCBF safety filter with one-step latency prediction and recovery (see the module docstring)."""

    name = "cbf"
    observation_type = "global"
    privileged = True

    def __init__(self, p1: float = 0.7535, p2: float = 0.6664, inflation: float = 1.05,
                 gamma_vmin: float = 1.0, gamma_vmax: float = 1.0, lambda_theta: float = 1.0,
                 lambda_v: float = 1.0, p_theta: float = 1.0, p_v: float = 1.0,
                 u1_bounds=(-0.25, 0.25), u2_bounds=(-0.5, 0.5), v_bounds=(0.0, 2.0),
                 active_atol: float = 1e-3, active_rtol: float = 0.0, low_speed_stop: bool = False,
                 max_obstacles: int = 64, eps: float = 1e-6, predict_latency: bool = True,
                 recovery: bool = True, v_stuck: float = 0.05, lap_guess: float = 0.1,
                 goal_aware_margin: bool = True) -> None:
        super().__init__()
        self.p1 = _finite("p1 (class-K gain)", p1, positive=True)
        self.p2 = _finite("p2 (class-K gain)", p2, positive=True)
        k = _finite("inflation", inflation)
        if not k >= 1:
            raise ValueError(f"inflation must be >= 1 (1 = the obstacle itself), got {inflation!r}")
        self.k = k
        self.gamma_vmin = _finite("gamma_vmin", gamma_vmin, positive=True)
        self.gamma_vmax = _finite("gamma_vmax", gamma_vmax, positive=True)
        self.lambda_theta = _finite("lambda_theta", lambda_theta, positive=True)
        self.lambda_v = _finite("lambda_v", lambda_v, positive=True)
        self.p_theta = _finite("p_theta", p_theta, positive=True)
        self.p_v = _finite("p_v", p_v, positive=True)
        self.u1_min, self.u1_max = _range("u1_bounds", u1_bounds)
        self.u2_min, self.u2_max = _range("u2_bounds", u2_bounds)
        self.v_min, self.v_max = _range("v_bounds", v_bounds)
        if not (self.u1_min <= 0 <= self.u1_max and self.u2_min < 0 < self.u2_max):
            raise ValueError(f"the control box must contain 0 in u1 and allow braking and accelerating in u2, "
                             f"got u1_bounds={u1_bounds!r}, u2_bounds={u2_bounds!r}")
        self.active_atol = _finite("active_atol", active_atol, nonneg=True)
        self.active_rtol = _finite("active_rtol", active_rtol, nonneg=True)
        self.low_speed_stop = bool(low_speed_stop)
        if int(max_obstacles) != max_obstacles or max_obstacles < 0:
            raise ValueError(f"max_obstacles must be an integer >= 0, got {max_obstacles!r}")
        self.max_obstacles = int(max_obstacles)
        self.eps = _finite("eps", eps, positive=True)
        self.predict_latency = bool(predict_latency)
        self.recovery = bool(recovery)
        self.v_stuck = _finite("v_stuck", v_stuck, nonneg=True)
        self.lap_guess = _finite("lap_guess", lap_guess, positive=True)
        self.goal_aware_margin = bool(goal_aware_margin)
        self._system = Dubins4D(v_min=self.v_min, v_max=self.v_max, u1_min=self.u1_min, u1_max=self.u1_max,
                                u2_min=self.u2_min, u2_max=self.u2_max)
        self._solver = None
        self._counts = self._zero_counts()

    @staticmethod
    def _zero_counts():
        return {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0, "recoveries": 0, "recovery_entries": 0}

    # ------------------------------------------------------------------ setup
    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        priv = self._privileged()
        obstacles = np.asarray(priv["obstacles"], float).reshape(-1, 3)
        if obstacles.shape[0] > self.max_obstacles:
            raise ValueError(f"{obstacles.shape[0]} obstacles exceed this CBF guardian's QP limit of {self.max_obstacles}")
        self.obstacles = obstacles
        self.goal = np.asarray(priv["goal"], float)
        r = obstacles[:, 2]
        R = self.k * r
        if self.goal_aware_margin and self.goal.shape[0] >= 3:
            far = np.hypot(self.goal[0] - obstacles[:, 0], self.goal[1] - obstacles[:, 1]) + self.goal[2]
            R = np.maximum(r, np.minimum(R, 0.5 * (r + far)))
        self.radii = R  # the inflated radius of each obstacle's barrier
        self._counts = self._zero_counts()
        self._pending = np.zeros(2)  # the control acting during the coming lap (the driver's: unknown, 0)
        self._last_time = float(priv.get("sim_time", 0.0))
        self._lap = self.lap_guess
        self._recovering = None  # index of the obstacle being recovered from
        K = obstacles.shape[0]
        self.K = K
        # rows: 0..K-1 barriers (u1, u2); K u1 box; K+1 u2 box+speed; K+2 heading CLF (u1, d_th); K+3 speed CLF (u2, d_v)
        m = K + 4
        rows = [np.r_[np.arange(K), K, K + 2], np.r_[np.arange(K), K + 1, K + 3], [K + 2], [K + 3]]
        self._indices = np.concatenate(rows).astype(np.int32)
        self._indptr = np.cumsum([0] + [len(r) for r in rows]).astype(np.int32)
        self._Ax = np.ones(self._indices.shape[0])
        self._Ax[self._indptr[2]] = -1.0  # d_th in the heading CLF
        self._Ax[self._indptr[3]] = -1.0  # d_v in the speed CLF
        A = sp.csc_matrix((self._Ax.copy(), self._indices, self._indptr), shape=(m, 4))
        P = sp.diags([2.0, 2.0, 2.0 * self.p_theta, 2.0 * self.p_v], format="csc")
        self._l = np.full(m, -np.inf)
        self._u = np.full(m, np.inf)
        self._l[K], self._u[K] = self.u1_min, self.u1_max
        self._l[K + 1], self._u[K + 1] = self.u2_min, self.u2_max
        self._u[K + 2] = self._u[K + 3] = 0.0
        self._solver = osqp.OSQP()
        self._solver.setup(P, np.zeros(4), A, self._l, self._u, verbose=False, eps_abs=self.eps, eps_rel=self.eps,
                           polishing=True, warm_starting=True, max_iter=4000)
        self._m = m

    # ------------------------------------------------------------------ the QP
    def barriers(self, state) -> np.ndarray:
        """``b_i`` at ``state`` for every obstacle (``>= 0``: outside the inflated circle)."""
        x, y = float(state[0]), float(state[1])
        o = self.obstacles
        return (x - o[:, 0]) ** 2 + (y - o[:, 1]) ** 2 - self.radii ** 2

    def rows(self, state):
        """Dense ``(G, h)`` of ``G z <= h`` at ``state`` (the same rows the OSQP problem holds);
        for tests against independent solvers."""
        x, y, th, v = (float(s) for s in state[:4])
        ox, oy, r = self.obstacles[:, 0], self.obstacles[:, 1], self.obstacles[:, 2]
        dx, dy = x - ox, y - oy
        c, s = math.cos(th), math.sin(th)
        b = dx * dx + dy * dy - self.radii ** 2
        lfb = 2.0 * v * (dx * c + dy * s)
        lf2b = 2.0 * v * v
        g1 = 2.0 * v * (dy * c - dx * s)
        g2 = 2.0 * (dx * c + dy * s)
        h_bar = lf2b + self.p1 * lfb + self.p2 * (lfb + self.p1 * b)
        K = self.K
        G = np.zeros((K + 6, 4))
        h = np.zeros(K + 6)
        G[:K, 0], G[:K, 1], h[:K] = -g1, -g2, h_bar
        # u1 box, u2 box merged with the speed barriers (as two rows each for a dense solver)
        G[K, 0], h[K] = 1.0, self.u1_max
        G[K + 1, 0], h[K + 1] = -1.0, -self.u1_min
        G[K + 2, 1], h[K + 2] = 1.0, min(self.u2_max, self.gamma_vmax * (self.v_max - v))
        G[K + 3, 1], h[K + 3] = -1.0, -max(self.u2_min, -self.gamma_vmin * (v - self.v_min))
        xh, yh = self.goal[0] - x, self.goal[1] - y
        d2 = xh * xh + yh * yh
        d = math.sqrt(d2)
        thw = (th + math.pi) % (2 * math.pi) - math.pi
        e = thw - desired_heading(thw, math.atan2(yh, xh))
        lfv = 2.0 * v * e * (xh * math.sin(thw) - yh * math.cos(thw)) / d2 if d2 > 0 else 0.0
        G[K + 4, 0], G[K + 4, 2], h[K + 4] = 2.0 * e, -1.0, -lfv - self.lambda_theta * e * e
        v_d = min((d / 2.0) ** 2, d / 2.0)
        ev = v - v_d
        G[K + 5, 1], G[K + 5, 3], h[K + 5] = 2.0 * ev, -1.0, -self.lambda_v * ev * ev
        return G, h

    def solve(self, state):
        """OSQP solution ``z*`` at ``state`` and the dense rows ``(G, h)``; ``z* = None`` if it failed."""
        G, h = self.rows(state)
        K = self.K
        Ax = self._Ax
        p = self._indptr
        Ax[p[0]:p[0] + K] = G[:K, 0]
        Ax[p[0] + K + 1] = G[K + 4, 0]  # heading CLF coefficient of u1
        Ax[p[1]:p[1] + K] = G[:K, 1]
        Ax[p[1] + K + 1] = G[K + 5, 1]  # speed CLF coefficient of u2
        u = self._u
        u[:K] = h[:K]
        self._l[K + 1], u[K + 1] = -h[K + 3], h[K + 2]
        if self._l[K + 1] > u[K + 1]:
            self._l[K + 1] = u[K + 1]
        u[K + 2], u[K + 3] = h[K + 4], h[K + 5]
        self._solver.update(Ax=Ax, l=self._l, u=u)
        res = self._solver.solve(raise_error=False)
        self._counts["qp_solves"] += 1
        if res.info.status_val not in (1, 2) or res.x is None or not np.all(np.isfinite(res.x)):
            return None, G, h
        return np.asarray(res.x), G, h

    # ------------------------------------------------------------------ latency
    def predict(self, state, control, lap: float) -> np.ndarray:
        """The exact state after ``lap`` seconds of ``control`` from ``state`` (heading wrapped)."""
        s = self._system.states_at(np.asarray(state, float)[None, :4], np.asarray(control, float)[None, :],
                                   np.array([float(lap)]))[0, 0].copy()
        s[2] = (s[2] + math.pi) % (2.0 * math.pi) - math.pi
        return s

    # ------------------------------------------------------------------ recovery
    def recovery_control(self, state, i: int, lap: float | None = None, side: float | None = None) -> np.ndarray:
        """The backup manoeuvre about obstacle ``i`` at ``state`` (module docstring): ``(u1, u2)``.
        ``side`` (+1: counter-clockwise tangent, -1: clockwise) overrides the choice of tangent."""
        x, y, th, v = (float(s) for s in state[:4])
        ox, oy = self.obstacles[i, :2]
        R = float(self.radii[i])
        dx, dy = x - ox, y - oy
        dist = math.hypot(dx, dy)
        if dist > 0:
            nx, ny = dx / dist, dy / dist
        else:  # at the centre: any direction is outward; take the heading
            nx, ny = math.cos(th), math.sin(th)
        c, s = math.cos(th), math.sin(th)
        hn = c * nx + s * ny  # outward component of the heading
        tx, ty = -ny, nx  # the counter-clockwise tangent
        if side is not None:
            pass
        elif v > self.v_stuck:
            side = 1.0 if c * tx + s * ty >= 0 else -1.0
        else:
            gx, gy = self.goal[0] - x, self.goal[1] - y
            side = 1.0 if gx * tx + gy * ty >= 0 else -1.0
        tx, ty = side * tx, side * ty
        self._last_side = side
        b = dx * dx + dy * dy - R * R
        if b < 0:
            tx, ty = tx + nx, ty + ny
        err = (math.atan2(ty, tx) - th + math.pi) % (2.0 * math.pi) - math.pi
        if hn < 0:  # turn the way that rotates the heading away from the centre, never through it
            away = ny * c - nx * s  # sin(normal angle - heading angle): > 0 turn left
            if away * err < 0:
                err += math.copysign(2.0 * math.pi, away)
        lap = self._lap if lap is None else lap
        u1 = min(max(err / lap, self.u1_min), self.u1_max)
        if hn < 0 and abs(err) > self.u1_max * lap:
            u2 = self.u2_min if v > self.v_min else 0.0
        else:
            u2 = max(0.0, min(self.u2_max, self.gamma_vmax * (self.v_max - v)))
            # accelerate only as far as every barrier row allows with this u1 (another
            # obstacle may lie ahead): row j reads G[j,0] u1 + G[j,1] u2 <= h_j
            G, h = self.rows(state)
            K = self.K
            lim = G[:K, 1] > 0
            if np.any(lim):
                cap = float(np.min((h[:K][lim] - G[:K, 0][lim] * u1) / G[:K, 1][lim]))
                if cap < u2:
                    u2 = max(cap, self.u2_min)
        return np.array([u1, u2])

    def _recovery_done(self, state, b, i) -> bool:
        if np.any(b < 0):
            return False
        x, y, th = float(state[0]), float(state[1]), float(state[2])
        ox, oy = self.obstacles[i, :2]
        dx, dy = x - ox, y - oy
        if dx * math.cos(th) + dy * math.sin(th) < 0:
            return False
        # the straight line to the goal centre must clear the inflated circle i
        gx, gy = self.goal[0] - x, self.goal[1] - y
        R2 = float(self.radii[i]) ** 2
        if (self.goal[0] - ox) ** 2 + (self.goal[1] - oy) ** 2 <= R2:
            return True  # the goal overlaps the margin: no detour can clear it; the QP takes over
        L2 = gx * gx + gy * gy
        t = 0.0 if L2 == 0 else min(1.0, max(0.0, -(dx * gx + dy * gy) / L2))
        px, py = dx + t * gx, dy + t * gy
        return px * px + py * py > R2

    def critical_obstacle(self, state) -> int:
        """The obstacle whose barrier row is hardest to satisfy at ``state``: the smallest
        ``h_i + max_u LgLf b_i . u`` over the control box and speed limits (negative: no
        admissible control satisfies row ``i``)."""
        G, h = self.rows(state)
        K = self.K
        u2_hi, u2_lo = h[K + 2], -h[K + 3]
        best = h[:K] - np.minimum(G[:K, 0] * self.u1_min, G[:K, 0] * self.u1_max) \
            - np.minimum(G[:K, 1] * u2_lo, G[:K, 1] * u2_hi)
        return int(np.argmin(best))

    def _recover(self, state):
        if self._recovering is None:
            self._counts["recovery_entries"] += 1
            self._recovering = self.critical_obstacle(state)
            self._side = None
            self._flips = 0
        self._counts["recoveries"] += 1
        u = self.recovery_control(state, self._recovering, side=self._side)
        self._side = self._last_side  # keep going round the same way
        if abs(u[0]) * self._lap < 1e-3 and state[3] + u[1] * self._lap <= self.v_stuck:
            # stalled: stopped, facing the target and blocked by another obstacle's row (two
            # overlapping obstacles form a notch).  Go round the other way; if that is blocked
            # too, recover from the obstacle that now blocks.
            if self._flips == 0:
                self._flips = 1
                self._side = -self._side
            else:
                self._recovering = self.critical_obstacle(state)
                self._side = None
                self._flips = 0
            u = self.recovery_control(state, self._recovering, side=self._side)
            self._side = self._last_side
        elif state[3] > self.v_stuck:
            self._flips = 0
        return u

    # ------------------------------------------------------------------ decision
    def _emit(self, u1, u2):
        u1 = float(np.clip(u1, self.u1_min, self.u1_max))
        u2 = float(np.clip(u2, self.u2_min, self.u2_max))
        self._pending = np.array([u1, u2])
        return active_action(u1, u2)

    def _inactive(self):
        self._pending = np.zeros(2)
        return inactive_action()

    def act(self, observation, info=None):
        priv = self._privileged()
        state = np.asarray(priv["state"], float)
        if not np.all(np.isfinite(state)):
            self._counts["nan_states"] += 1
            return self._emit(0.0, self.u2_min)
        if self.predict_latency:
            t = float(priv.get("sim_time", self._last_time))
            if t > self._last_time:
                self._lap = t - self._last_time
            self._last_time = t
            state = self.predict(state, self._pending, self._lap)
        return self._decide(state)

    def _decide(self, state):
        """The decision for the state the action will act from (already predicted)."""
        if self.low_speed_stop and state[3] < 0.05:
            return self._emit(0.0, self.u2_min)
        if self.K == 0:
            return self._inactive()
        if self.recovery and self._recovering is not None:
            b = self.barriers(state)
            if not self._recovery_done(state, b, self._recovering):
                return self._emit(*self._recover(state))
            self._recovering = None
        z, G, h = self.solve(state)
        if z is None:
            self._counts["qp_fallbacks"] += 1
            if self.recovery:
                return self._emit(*self._recover(state))
            return self._emit(0.0, self.u2_min)
        gap = h[: self.K] - G[: self.K] @ z
        if np.any(np.abs(gap) <= self.active_atol + self.active_rtol * np.abs(h[: self.K])):
            if self.recovery and state[3] + z[1] * self._lap <= self.v_stuck:
                return self._emit(*self._recover(state))
            return self._emit(z[0], z[1])
        return self._inactive()

    def stats(self) -> dict:
        return dict(self._counts)


class CBFPaperGuardian(CBFGuardian):
    """The paper's CBF rule (the previous ``cbf`` exactly): the QP at the observed state, maximum
    braking when it is infeasible, no recovery."""

    name = "cbf-paper"

    def __init__(self, *args, predict_latency: bool = False, recovery: bool = False,
                 goal_aware_margin: bool = False, **kwargs) -> None:
        super().__init__(*args, predict_latency=predict_latency, recovery=recovery,
                         goal_aware_margin=goal_aware_margin, **kwargs)
