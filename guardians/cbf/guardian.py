"""The HOCBF guardians ``cbf`` and ``cbf-paper``: configuration, latency prediction and the decision.

The rule and the defaults: :class:`CBFGuardian`; the settings in :mod:`rmm_guardians.cbf.settings`;
why: docs/decisions/0014-cbf-safety-filter.md.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.machine_independent import matvec
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_guardians._checks import settings_signature
from rmm_guardians.cbf.backend import dubins4d_qp
from rmm_guardians.cbf.barrier import (
    BarrierRows,
    HOCBFParams,
    any_row_active,
    barrier_values,
    critical_obstacle,
    inflated_radii,
)
from rmm_guardians.cbf.recovery import recovery_control, recovery_done
from rmm_guardians.cbf.settings import CBF_PRESETS, REFERENCES, CBFSettings, box_problem
from rmm_guardians.dispatch import DynamicsDispatch
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import dubins4d_only

__all__ = ["CBFGuardian", "CBFPaperGuardian", "REFERENCES"]


class CBFGuardian(DynamicsDispatch, PrivilegedGuardian):
    """HOCBF safety filter with one-step latency prediction and recovery.

    ``reference="nominal"`` (default) minimises ``|u - u_nom|^2``, ``u_nom`` the driver's
    ``info["nominal_control"]`` (a ``ValueError`` naming the key when an env gives none), under
    the barrier rows of :func:`rmm_guardians.cbf.barrier.barrier_rows`; a nominal control that
    satisfies every row passes without a solve.  ``"clf"`` re-derives a goal-seeking control as
    the paper did (``minimise u1^2 + u2^2 + p_theta d_th^2 + p_v d_v^2`` with the heading and
    speed CLFs).  The guardian takes control, applying the QP's ``(u1, u2)``, when a barrier row is
    active at the solution, ``|G_i z* - h_i| <= active_atol + active_rtol |h_i|``; otherwise the
    driver keeps control.

    * ``predict_latency``: the QP is solved at the state predicted one lap ahead under the
      control acting during the lap (its own last action, or ``u_nom``; ``clf`` takes zero); the lap
      is measured from the simulated times, ``lap_guess`` (0.1 s) before the first.
    * ``recovery``: when the QP is infeasible or fails, or a barrier row is active and the speed is
      left below ``v_stuck`` (0.05 m/s) after the lap, a backup manoeuvre about the obstacle whose
      row is hardest to satisfy (:mod:`rmm_guardians.cbf.recovery`), until the car is outside every
      margin, its heading not into that obstacle, and the straight line to the goal clears it.
      Without it (``cbf-paper``) an infeasible QP brakes at maximum with no turn.
    * ``goal_aware_margin``: each inflated radius is ``max(r, min(k r, (r + F) / 2))``, ``F`` the
      goal point farthest from the centre, so a margin never covers the goal.

    Defaults: ``p1 = 0.7535, p2 = 0.6664`` and ``inflation = 1.05`` (the paper's);
    ``gamma_vmin = gamma_vmax = lambda_theta = lambda_v = p_theta = p_v = 1`` (the paper's, the
    driver's too); ``active_atol = 1e-3``, ``active_rtol = 0``; ``eps = 1e-6`` (OSQP's tolerance,
    solutions polished); ``max_obstacles = 64`` (the QP is sized once per episode);
    ``low_speed_stop=True`` restores the original's full stop below 0.05 m/s.  ``u1_bounds`` /
    ``u2_bounds`` (default ``None``: the action space's, read at ``reset``) and ``v_bounds``
    (default ``None``: the Dubins4D system's speed range) override the bounds.  ``solver``:
    ``"osqp"`` or ``"qpsolvers:<name>"`` (:mod:`rmm_guardians.cbf.backend`).  ``maze`` /
    ``quadrotor``: the arguments of the maze car's and the quadrotor's guardian (``False``
    refuses those envs); ``solver``, ``eps``, ``predict_latency`` and ``lap_guess`` are shared.

    ``stats()``: ``qp_fallbacks`` (every QP that failed or was infeasible), ``recoveries`` (steps
    spent recovering), ``recovery_entries``, ``nan_states`` (a state with NaN brakes at maximum),
    ``qp_solves``.  Bad arguments are refused at construction naming the value; an action space
    without two controls, or whose box does not contain ``u1 = 0`` and both signs of ``u2``, is
    refused at ``reset``."""

    name = "cbf"
    method = "cbf"  #: its parts serve the other dynamics (rmm_guardians.parts: the maze car, the quadrotor)
    own_check = staticmethod(dubins4d_only)

    preset = "cbf"  #: the CBFSettings preset the keyword arguments change

    # the control box, set by _bounds at reset
    u1_min: float
    u1_max: float
    u2_min: float
    u2_max: float

    def __init__(self, settings: CBFSettings | None = None, **options) -> None:
        """``settings`` (default: the class's :attr:`preset`) with ``options``, any of
        :class:`~rmm_guardians.cbf.settings.CBFSettings`' fields, changed."""
        super().__init__()
        s = self.settings = (settings if settings is not None else CBF_PRESETS[self.preset]).replace(**options)
        self.reference, self.solver = s.reference, s.solver
        shared = {"solver": s.solver, "eps": s.eps, "predict_latency": s.predict_latency, "lap_guess": s.lap_guess}
        self._init_parts(s, shared)
        self.p1, self.p2, self.k = s.p1, s.p2, s.inflation
        self.gamma_vmin, self.gamma_vmax, self.lambda_theta, self.lambda_v = (
            s.gamma_vmin,
            s.gamma_vmax,
            s.lambda_theta,
            s.lambda_v,
        )
        self.p_theta, self.p_v = s.p_theta, s.p_v
        self._u1_arg, self._u2_arg = s.u1_bounds, s.u2_bounds
        self.v_min, self.v_max = s.speed_bounds
        self.active_atol, self.active_rtol, self.low_speed_stop = s.active_atol, s.active_rtol, s.low_speed_stop
        self.max_obstacles, self.eps, self.v_stuck, self.lap_guess = s.max_obstacles, s.eps, s.v_stuck, s.lap_guess
        self.predict_latency, self.recovery, self.goal_aware_margin = s.predict_latency, s.recovery, s.goal_aware_margin
        self._qp = None
        self._counts = self._zero_counts()
        self._decided: np.ndarray | None = None  # the state the last decision acted from (signals())

    @staticmethod
    def _zero_counts():
        return {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0, "recoveries": 0, "recovery_entries": 0}

    # ------------------------------------------------------------------ setup
    def _bounds(self) -> None:
        """The control box (the action space's unless overridden), the rows' parameters and the
        dynamics used for the latency prediction."""
        space = self.require_action_space(controls=2)  # (turn rate, acceleration)
        lo, hi = space.control_low, space.control_high
        u1 = self._u1_arg or (float(lo[0]), float(hi[0]))
        u2 = self._u2_arg or (float(lo[1]), float(hi[1]))
        problem = box_problem(u1, u2)
        if problem:
            raise ValueError(
                f"guardian {self.name!r}: {problem}, got u1 in {list(u1)} and u2 in {list(u2)} "
                f"(from the action space {space} unless given)"
            )
        (self.u1_min, self.u1_max), (self.u2_min, self.u2_max) = u1, u2
        self.params = HOCBFParams(
            self.p1,
            self.p2,
            self.gamma_vmin,
            self.gamma_vmax,
            self.lambda_theta,
            self.lambda_v,
            self.u1_min,
            self.u1_max,
            self.u2_min,
            self.u2_max,
            self.v_min,
            self.v_max,
        )
        self._system = Dubins4D(
            v_min=self.v_min,
            v_max=self.v_max,
            u1_min=self.u1_min,
            u1_max=self.u1_max,
            u2_min=self.u2_min,
            u2_max=self.u2_max,
        )

    def reset(self, **kwargs) -> None:
        if self._dispatch_reset(kwargs):
            return
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        self._bounds()
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        obstacles = np.asarray(priv["obstacles"], float).reshape(-1, 3)
        if obstacles.shape[0] > self.max_obstacles:
            raise ValueError(
                f"{obstacles.shape[0]} obstacles exceed this CBF guardian's QP limit of {self.max_obstacles}"
            )
        self.obstacles = obstacles
        self.goal = np.asarray(priv["goal"], float)
        self.radii = inflated_radii(obstacles, self.goal, self.k, self.goal_aware_margin)
        self._rows = BarrierRows(obstacles, self.radii, self.goal, self.params)
        self._counts = self._zero_counts()
        self._pending = None  # the guardian's control acting during the coming lap; None: the driver's
        self.start_laps(self.lap_guess, since=priv.get("sim_time", 0.0))
        self._recovering = None  # index of the obstacle being recovered from
        self._decided = None
        self.K = obstacles.shape[0]
        self._qp = dubins4d_qp(self.solver, self.K, self.params, self.p_theta, self.p_v, self.eps)

    # ------------------------------------------------------------------ the barrier maths and the QP
    def barriers(self, state) -> np.ndarray:
        """``b_i`` at ``state`` for every obstacle (``>= 0``: outside the inflated circle)."""
        return barrier_values(state, self.obstacles, self.radii)

    def rows(self, state):
        """Dense ``(G, h)`` of ``G z <= h`` at ``state`` (the same rows the OSQP problem holds);
        for tests against independent solvers."""
        return self._rows(state)

    def solve(self, state, u_ref=None):
        """OSQP solution ``z*`` at ``state`` and the dense rows ``(G, h)``; ``z* = None`` if it
        failed.  ``u_ref``: the control to filter (``|u - u_ref|^2``, no CLF rows); ``None``:
        the paper's CBF-CLF problem."""
        G, h = self.rows(state)
        z = self._qp.solve(G, h, u_ref)
        self._counts["qp_solves"] += 1
        return z, G, h

    def critical_obstacle(self, state) -> int:
        """The obstacle whose barrier row is hardest to satisfy at ``state`` (see
        :func:`rmm_guardians.cbf.barrier.critical_obstacle`)."""
        G, h = self.rows(state)
        return critical_obstacle(G, h, self.params)

    # ------------------------------------------------------------------ latency
    def predict(self, state, control, lap: float) -> np.ndarray:
        """The exact state after ``lap`` seconds of ``control`` from ``state`` (heading wrapped)."""
        s = self._system.state_after(np.asarray(state, float)[:4], control, lap)
        s[2] = (s[2] + math.pi) % (2.0 * math.pi) - math.pi
        return s

    # ------------------------------------------------------------------ recovery
    def recovery_control(self, state, i: int, lap: float | None = None, side: float | None = None) -> np.ndarray:
        """The backup manoeuvre about obstacle ``i`` at ``state`` (:mod:`rmm_guardians.cbf`): ``(u1, u2)``.
        ``side`` (+1: counter-clockwise tangent, -1: clockwise) overrides the choice of tangent."""
        if lap is None:
            lap = self._measured_lap
            assert lap is not None  # reset's start_laps set the guess
        u, self._last_side = recovery_control(
            state,
            i,
            self.obstacles,
            self.radii,
            self.goal,
            self.params,
            lap,
            self.v_stuck,
            side,
            rows=self._rows,
        )
        return u

    def _recover(self, state):
        if self._recovering is None:
            self._counts["recovery_entries"] += 1
            self._recovering = self.critical_obstacle(state)
            self._side = None
            self._flips = 0
        self._counts["recoveries"] += 1
        u = self.recovery_control(state, self._recovering, side=self._side)
        self._side = self._last_side  # keep going round the same way
        if abs(u[0]) * self._measured_lap < 1e-3 and state[3] + u[1] * self._measured_lap <= self.v_stuck:
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
        u1 = min(max(float(u1), self.u1_min), self.u1_max)
        u2 = min(max(float(u2), self.u2_min), self.u2_max)
        self._pending = np.array([u1, u2])
        return self.action_space.active(self._pending)

    def _inactive(self):
        self._pending = None
        return self.action_space.inactive()

    def nominal(self, info) -> np.ndarray | None:
        """The driver's control this step, ``info["nominal_control"]`` (``reference="nominal"``;
        a ``ValueError`` naming the key when the env gives none), or ``None`` (``"clf"``)."""
        if self.reference != "nominal":
            return None
        u = None if not isinstance(info, dict) else info.get("nominal_control")
        if u is None:
            raise ValueError(
                f"guardian {self.name!r} filters the driver's control, info['nominal_control'] (the "
                f"parallel-autonomy contract), but the step's info has none (keys: "
                f"{sorted(info) if isinstance(info, dict) else info!r}); use reference='clf' for an env "
                "without it"
            )
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape != (2,) or not all(map(math.isfinite, u.tolist())):
            raise ValueError(
                f"info['nominal_control'] must be 2 finite numbers (u1, u2), got {info['nominal_control']!r}"
            )
        return u

    def act(self, observation, info=None):
        if self.delegate is not None:
            return self.delegate.act(observation, info)
        u_nom = self.nominal(info)
        priv = self._privileged()
        state = np.asarray(priv["state"], float)
        if not self.finite_state(state):
            self._decided = None
            return self._emit(0.0, self.u2_min)
        if self.predict_latency:
            self.measure_lap(priv)
            # the control acting during the coming lap: the guardian's own last one, or the
            # driver's, which is the nominal control at this state (unknown to "clf": 0)
            during = self._pending if self._pending is not None else (u_nom if u_nom is not None else np.zeros(2))
            state = self.predict(state, during, self._measured_lap)
        return self._decide(state, u_nom)

    def warm_up(self, observation, info=None) -> None:
        """One decision, then the paths a first decision far from every obstacle skips: the QP
        (its compiled matrix fill) with and without a control to filter, and the recovery
        manoeuvre; the caller resets the guardian afterwards."""
        self.act(observation, info)
        if self.delegate is not None or self.K == 0:
            return
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        state = np.asarray(self._privileged()["state"], float)
        if all(map(math.isfinite, state.tolist())):
            self.solve(state)
            self.solve(state, np.zeros(2))
            self.recovery_control(state, 0)

    def _decide(self, state, u_nom=None):
        """The decision for the state the action will act from (already predicted)."""
        self._decided = state  # kept for signals() only
        if self.low_speed_stop and state[3] < 0.05:
            return self._emit(0.0, self.u2_min)
        if self.K == 0:
            return self._inactive()
        if self.recovery and self._recovering is not None:
            b = self.barriers(state)
            if not recovery_done(state, b, self._recovering, self.obstacles, self.radii, self.goal):
                return self._emit(*self._recover(state))
            self._recovering = None
        z = None
        if u_nom is not None:
            # a nominal control that satisfies every row is the filter's solution itself (the
            # QP's unconstrained optimum is feasible): no solve
            G, h = self.rows(state)
            z = np.array([u_nom[0], u_nom[1], 0.0, 0.0])
            if not np.all(matvec(G[: self.K + 4], z) <= h[: self.K + 4] + self.eps):  # within the QP's tolerance
                z = None
        if z is None:
            z, G, h = self.solve(state, u_nom)
        if z is None:
            self._counts["qp_fallbacks"] += 1
            if self.recovery:
                return self._emit(*self._recover(state))
            return self._emit(0.0, self.u2_min)
        if any_row_active(G, h, z, self.K, self.active_atol, self.active_rtol):
            if self.recovery and state[3] + z[1] * self._measured_lap <= self.v_stuck:
                return self._emit(*self._recover(state))
            return self._emit(z[0], z[1])
        return self._inactive()

    def stats(self) -> dict:
        if self.delegate is not None:
            return self.delegate.stats()
        return dict(self._counts)

    def signals(self) -> dict[str, float]:
        """``barrier_min``: the smallest obstacle barrier ``b_i`` (m^2; below 0: inside an inflated
        circle) at the state the last decision acted from (the latency-predicted one), ``nan``
        before a decision or without obstacles; ``qp_fallbacks``: the episode's infeasible QPs so far."""
        if self.delegate is not None:
            return self.delegate.signals()
        b = math.nan
        if self._decided is not None and self.K > 0:
            b = float(np.min(self.barriers(self._decided)))
        return {"barrier_min": b, "qp_fallbacks": float(self._counts["qp_fallbacks"])}

    def alarm(self) -> tuple[float, float] | None:
        """``(-barrier_min, 0)``: up when the state the last decision acted from is inside an
        inflated circle (or the delegate's, on the maze car and the quadrotor)."""
        if self.delegate is not None:
            return self.delegate.alarm()
        return -self.signals()["barrier_min"], 0.0


# a function's attributes live in its __dict__ (the type checker knows no __signature__ on a method)
CBFGuardian.__init__.__dict__["__signature__"] = settings_signature(CBFSettings, CBF_PRESETS["cbf"])


class CBFPaperGuardian(CBFGuardian):
    """The paper's CBF rule (the previous ``cbf`` exactly): the CBF-CLF QP at the observed state,
    maximum braking when it is infeasible, no recovery (the ``cbf-paper`` preset)."""

    name = "cbf-paper"
    preset = "cbf-paper"
