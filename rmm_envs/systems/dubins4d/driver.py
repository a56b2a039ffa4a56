"""The "reckless driver": a CLF-QP that steers to the goal and ignores obstacles.

From Xiao & Belta (high-order CBFs, Sec. V.B) as used by the paper's environment: over
``z = (u1, u2, d_theta, d_v)`` (controls and two CLF slacks) it minimises
``u1^2 + u2^2 + p_theta d_theta^2 + p_v d_v^2`` under the speed barriers, the control box, a
heading CLF toward the goal and a speed CLF toward ``v_d = (d / 10)^2``.

:func:`clf_qp` solves it exactly for ``N`` states in one compiled loop (the default,
``solver="closed_form"``); ``solver="osqp"`` hands the same rows to OSQP, to check it.
:class:`CLFDriver` is the env's driver, :class:`DriverParams` its gains, :func:`desired_heading`
the heading it steers to.  The QP in full: :func:`clf_qp`; how the closed form is derived: "Design
notes" at the end.  Why a closed form: docs/decisions/0020-reckless-drivers.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from rmm_envs.systems.dubins4d.dynamics import desired_heading  # the CLF's target heading, shared with the cbf guardian
from rmm_envs.systems.dubins4d.dynamics import desired_heading_compiled as _desired_heading

if TYPE_CHECKING:
    import osqp

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; the Python loop still works
    njit = None

__all__ = ["CLFDriver", "DriverParams", "SOLVERS", "clf_qp", "desired_heading"]

SOLVERS = ("closed_form", "osqp")


@dataclass(frozen=True)
class DriverParams:
    gamma_vmin: float = 1.0
    gamma_vmax: float = 1.0
    lambda_theta: float = 1.0
    lambda_v: float = 1.0
    p_theta: float = 1.0
    p_v: float = 1.0

    def __post_init__(self) -> None:
        # A NaN or infinite gain would silently turn a constraint off (or make the QP fail);
        # slack weights must be > 0 for the QP to stay strictly convex.
        for name in ("gamma_vmin", "gamma_vmax", "lambda_theta", "lambda_v", "p_theta", "p_v"):
            v = getattr(self, name)
            positive = name.startswith("p_")
            if not (isinstance(v, (int, float)) and math.isfinite(v) and (v > 0 if positive else v >= 0)):
                raise ValueError(
                    f"driver parameter {name} must be a finite number {'> 0' if positive else '>= 0'}, got {v!r}"
                )

    def as_array(self) -> np.ndarray:
        return np.array([self.gamma_vmin, self.gamma_vmax, self.lambda_theta, self.lambda_v, self.p_theta, self.p_v])


def _clf_rows(x, y, theta, v, gx, gy, lim, gain):
    """The QP's data at one state: ``(a1, b1, a2, b2, l2, h2)``, rows ``a u - d <= b`` and the
    ``u2`` interval.  ``lim = (u1_min, u1_max, u2_min, u2_max, v_min, v_max)``, ``gain =
    (gamma_vmin, gamma_vmax, lambda_theta, lambda_v, p_theta, p_v)``."""
    xh = gx - x
    yh = gy - y
    d2 = xh * xh + yh * yh
    d = math.sqrt(d2)
    v_d = (d / 10.0) ** 2
    th = (theta + math.pi) % (2.0 * math.pi) - math.pi
    e = th - _desired_heading(th, math.atan2(yh, xh))
    lfv = 2.0 * v * e * (xh * math.sin(th) - yh * math.cos(th)) / d2 if d2 > 0 else 0.0
    ev = v - v_d
    l2 = max(lim[2], -gain[0] * (v - lim[4]))
    h2 = min(lim[3], gain[1] * (lim[5] - v))
    if l2 > h2:  # speed outside its bounds: keep the problem feasible, favour the barrier
        l2 = min(max(0.0, lim[2]), lim[3])
        h2 = l2
    return 2.0 * e, -lfv - gain[2] * (e * e), 2.0 * ev, -gain[3] * (ev * ev), l2, h2


def _min_box_slack(a, b, p, lo, hi):
    """Exact minimiser of ``u^2 + p d^2`` s.t. ``lo <= u <= hi``, ``a u - d <= b`` (``p > 0``)."""
    u = p * a * min(b, 0.0) / (1.0 + p * a * a)
    u = min(max(u, lo), hi)
    return u, max(0.0, a * u - b)


def _clf_qp_loop(states, goals, lim, gain, out):
    for n in range(states.shape[0]):
        a1, b1, a2, b2, l2, h2 = _clf_rows(
            states[n, 0], states[n, 1], states[n, 2], states[n, 3], goals[n, 0], goals[n, 1], lim, gain
        )
        out[n, 0], out[n, 2] = _min_box_slack(a1, b1, gain[4], lim[0], lim[1])
        out[n, 1], out[n, 3] = _min_box_slack(a2, b2, gain[5], l2, h2)
    return out


if njit is not None:  # one source: the compiled loop runs these very functions
    _clf_rows = njit(cache=True)(_clf_rows)
    _min_box_slack = njit(cache=True)(_min_box_slack)
    _clf_qp_loop = njit(cache=True)(_clf_qp_loop)


def clf_qp(states, goals, lim, gain, out=None) -> np.ndarray:
    """Exact solutions ``z = (u1, u2, d_theta, d_v)`` of the driver's QP at ``N`` states::

        minimise   u1^2 + u2^2 + p_theta d_theta^2 + p_v d_v^2
        subject to u2 <= gamma_vmax (v_max - v)                    (speed-max barrier)
                   -u2 <= gamma_vmin (v - v_min)                   (speed-min barrier)
                   u1_min <= u1 <= u1_max,  u2_min <= u2 <= u2_max (control box)
                   2 (theta - theta_d) u1 - d_theta <= -LfV_theta - lambda_theta V_theta   (heading CLF)
                   2 (v - v_d) u2 - d_v <= -lambda_v V_v                                (speed CLF)

    with ``V_theta = (theta - theta_d)^2``, ``theta_d`` the bearing of the goal
    (:func:`desired_heading`, with the original's literal +-1.5 pi rule near the branch cut),
    ``LfV_theta = 2 v (theta - theta_d) (xh sin theta - yh cos theta) / d^2``, ``v_d = (d / 10)^2``
    (unclipped) and ``V_v = (v - v_d)^2``.  The speed barriers and the ``u2`` box are one interval
    ``[l2, h2]`` for ``u2`` (the tighter bounds); when the speed is outside its bounds the interval
    is empty and is replaced by the single point ``clip(0, u2_min, u2_max)`` (the problem stays
    feasible, favouring the barrier).

    Args:
        states: ``(N, 4+)`` states ``(x, y, theta, v)``.
        goals: ``(N, 2+)`` goal centres.
        lim: ``(u1_min, u1_max, u2_min, u2_max, v_min, v_max)``.
        gain: :meth:`DriverParams.as_array`.
        out: optional ``(N, 4)`` float array to write into.

    Returns ``(N, 4)``; the controls are inside the control box.
    """
    states = np.ascontiguousarray(states, dtype=float)
    goals = np.ascontiguousarray(goals, dtype=float)
    if (
        states.ndim != 2
        or states.shape[1] < 4
        or goals.shape != (states.shape[0], goals.shape[1])
        or goals.shape[1] < 2
    ):
        raise ValueError(f"states must be (N, 4) and goals (N, 2), got {states.shape} and {goals.shape}")
    if out is None:
        out = np.empty((states.shape[0], 4))
    return _clf_qp_loop(states, goals, np.asarray(lim, dtype=float), np.asarray(gain, dtype=float), out)


class CLFDriver:
    """Goal-seeking CLF-QP controller.

    Args:
        u1_bounds, u2_bounds: control box.
        v_bounds: speed bounds used by the barrier rows.
        params: CLF/barrier gains and slack weights.
        eps: OSQP absolute and relative tolerance (``solver="osqp"`` only).
        solver: ``"closed_form"`` (exact, batched, the default) or ``"osqp"`` (for checking).
    """

    def __init__(
        self,
        u1_bounds=(-0.25, 0.25),
        u2_bounds=(-0.5, 0.5),
        v_bounds=(0.0, 2.0),
        params: DriverParams = DriverParams(),
        eps: float = 1e-7,
        solver: str = "closed_form",
    ) -> None:
        self.u1_min, self.u1_max = map(float, u1_bounds)
        self.u2_min, self.u2_max = map(float, u2_bounds)
        self.v_min, self.v_max = map(float, v_bounds)
        if self.u1_min > self.u1_max or self.u2_min > self.u2_max:
            raise ValueError(f"control bounds must satisfy min <= max, got {u1_bounds}, {u2_bounds}")
        if solver not in SOLVERS:
            raise ValueError(f"driver solver must be one of {SOLVERS}, got {solver!r}")
        self.params = params
        self.solver = solver
        self.lim = np.array([self.u1_min, self.u1_max, self.u2_min, self.u2_max, self.v_min, self.v_max])
        self.gain = params.as_array()
        self._eps = float(eps)
        self._solver: osqp.OSQP | None = None  # set up by reset() for the "osqp" solver
        self.reset()

    def reset(self) -> None:
        """Forget everything earlier solves left behind.

        The closed form keeps nothing.  OSQP keeps the last primal and dual iterates (the warm
        start) and its adapted step size ``rho`` between solves, so without a fresh problem an
        episode's controls would depend, in the last bits, on the episodes the same driver
        solved before.  The environment calls this at every ``reset()``.
        """
        if self.solver != "osqp":
            return
        # lazy: OSQP and scipy.sparse are heavy (about 0.3 s to import), used by this solver path only
        import osqp
        import scipy.sparse as sp

        p = self.params
        P = sp.diags([2.0, 2.0, 2.0 * p.p_theta, 2.0 * p.p_v], format="csc")
        # Rows: 0 u1 box; 1 u2 interval; 2 heading CLF; 3 speed CLF.  Fixed pattern
        # (column-major): col0 rows (0, 2); col1 rows (1, 3); col2 row 2; col3 row 3.
        self._Ax = np.array([1.0, 1.0, 1.0, 1.0, -1.0, -1.0])
        A = sp.csc_matrix(
            (self._Ax.copy(), np.array([0, 2, 1, 3, 2, 3], dtype=np.int32), np.array([0, 2, 4, 5, 6], dtype=np.int32)),
            shape=(4, 4),
        )
        self._l = np.array([self.u1_min, self.u2_min, -np.inf, -np.inf])
        self._u = np.array([self.u1_max, self.u2_max, 0.0, 0.0])
        self._solver = osqp.OSQP()
        self._solver.setup(
            P,
            np.zeros(4),
            A,
            self._l,
            self._u,
            verbose=False,
            eps_abs=self._eps,
            eps_rel=self._eps,
            polishing=True,
            warm_starting=True,
            max_iter=4000,
        )

    def _solve_osqp(self, state, goal_xy) -> np.ndarray:
        a1, b1, a2, b2, l2, h2 = _clf_rows(
            float(state[0]),
            float(state[1]),
            float(state[2]),
            float(state[3]),
            float(goal_xy[0]),
            float(goal_xy[1]),
            self.lim,
            self.gain,
        )
        self._Ax[1], self._Ax[3] = a1, a2
        self._l[1], self._u[1], self._u[2], self._u[3] = l2, h2, b1, b2
        assert self._solver is not None  # reset() set it up: this is the "osqp" solver
        self._solver.update(Ax=self._Ax, l=self._l, u=self._u)
        res = self._solver.solve(raise_error=False)
        z = res.x
        if z is None or not np.all(np.isfinite(z)):
            raise RuntimeError(f"driver QP failed ({res.info.status}) at state {np.asarray(state)[:4]}")
        return np.asarray(z, dtype=float)

    def solve(self, state, goal_xy) -> np.ndarray:
        """Return the QP's solution ``z = (u1, u2, d_theta, d_v)`` at ``state = (x, y, theta, v)``."""
        if self.solver == "osqp":
            return self._solve_osqp(state, goal_xy)
        return self.solve_batch(np.asarray(state, dtype=float)[None, :4], np.asarray(goal_xy, dtype=float)[None, :2])[0]

    def solve_batch(self, states, goals) -> np.ndarray:
        """Solutions ``(N, 4)`` at ``N`` states ``(N, 4)`` with goals ``(N, 2+)``."""
        if self.solver == "osqp":
            return np.array([self._solve_osqp(s, g) for s, g in zip(states, goals, strict=True)]).reshape(-1, 4)
        return clf_qp(states, goals, self.lim, self.gain)

    def control(self, state, goal_xy) -> np.ndarray:
        """The driver's ``(u1, u2)``, clipped to the control box."""
        return self.controls(np.asarray(state, dtype=float)[None, :4], np.asarray(goal_xy, dtype=float)[None, :2])[0]

    def controls(self, states, goals) -> np.ndarray:
        """The driver's controls ``(N, 2)`` at ``N`` states, clipped to the control box (the
        closed form is inside it already; OSQP's solutions may sit past it by its tolerance)."""
        z = self.solve_batch(states, goals)
        if self.solver == "osqp":
            return np.clip(z[:, :2], self.lim[[0, 2]], self.lim[[1, 3]])
        return z[:, :2]


# ------------------------------------------------------------------ design notes
#
# ## Exact solution (the default, ``solver="closed_form"``)
#
# The problem separates into two independent problems of the same form, ``(u1, d_theta)`` and
# ``(u2, d_v)``::
#
#     minimise u^2 + p d^2   subject to   lo <= u <= hi,   a u - d <= b
#
# For a fixed ``u`` the best slack is ``d = max(0, a u - b)``, leaving the convex, differentiable
# ``f(u) = u^2 + p max(0, a u - b)^2``.  If ``b >= 0``, ``u = 0`` is its minimiser (``f >= 0 =
# f(0)``); if ``b < 0``, setting ``f'(u) = 0`` on the branch ``a u > b`` gives ``u = p a b / (1 + p
# a^2)``, which is on that branch (``a u - b = -b / (1 + p a^2) > 0``).  Both cases are ``u* = p a
# min(b, 0) / (1 + p a^2)``; a convex function of one variable is minimised over an interval by
# clipping its minimiser, so::
#
#     u = clip(u*, lo, hi),   d = max(0, a u - b)
#
# which is the exact optimum (the active-set enumeration in ``tests/qp_reference.py`` and OSQP
# agree with it to 1e-6 on random instances; tested).  :func:`clf_qp` evaluates it for ``N``
# states in one compiled loop (numba; the same Python function runs uncompiled without numba),
# so the single environment (``N = 1``) and the vector environment (``N`` sub-environments) run
# the very same floating-point operations.  No state is kept between calls: an episode's
# floats depend only on its own seed.
#
# ## OSQP (``solver="osqp"``, for checking)
#
# The same rows handed to OSQP (tolerance ``eps``, default 1e-7, solutions polished): the problem
# is set up once with a fixed sparsity pattern and each call updates the constraint values and
# bounds and re-solves, warm-started from the previous solution.  :meth:`CLFDriver.reset` (called
# by the environment at every episode start) sets the problem up afresh, so warm starts never
# cross episodes.  This was the environment's solver before the closed form (about 20x slower per
# call); it stays available to check the closed form against an independent solver.
