"""Dubins4D: a car-like vehicle with heading-rate and acceleration controls.

State ``s = (x, y, theta, v)`` in metres, radians and m/s; control ``u = (u1, u2)``:

    x' = v cos(theta),   y' = v sin(theta),   theta' = u1,   v' = u2

with the speed held in ``[v_min, v_max]`` (default ``[0, 2]`` m/s): when the speed reaches a
bound, ``v'`` is zero for as long as ``u2`` pushes past it.  Control bounds: ``u1`` in
``[-0.25, 0.25]`` rad/s and ``u2`` in ``[-0.5, 0.5]`` m/s^2.  Propagation is **exact** for a
zero-order-hold control (closed-form integrals, no ODE solver).  All functions are batched
over ``N`` states of shape ``(N, 4)``.

The speed clamp, the exact propagation and its two code paths: :class:`Dubins4D`; why exact:
docs/decisions/0021-exact-models.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from math import factorial as f
from typing import Any

import numpy as np

from rmm_envs.autonomy import SafeDefault
from rmm_envs.machine_independent import wrap_angle

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; numpy alone still works
    njit = None

__all__ = [
    "CONTROLS",
    "DYNAMICS_NAME",
    "SERIES_COEFFICIENTS",
    "Dubins4D",
    "FullBraking",
    "desired_heading",
    "desired_heading_compiled",
    "segment_position",
    "wrap_angle",
]

_COMPILED_MAX_N = 8  # up to this many states per call, the compiled scalar path is faster


def _series_coefficients(j_max: int = 7):
    return (
        [(-1) ** j / f(2 * j + 1) for j in range(j_max)],
        [(-1) ** j / f(2 * j + 2) for j in range(j_max)],
        [(-1) ** j / (f(2 * j) * (2 * j + 2)) for j in range(j_max)],
        [(-1) ** j / (f(2 * j + 1) * (2 * j + 3)) for j in range(j_max)],
    )


_COEF = _series_coefficients()
_SERIES_MAX = 0.6  # 7 even/odd terms: truncation below 1e-15 for |phi| <= 0.6


def _horner(p: np.ndarray, coef) -> np.ndarray:
    acc = np.full_like(p, coef[-1])
    for c in coef[-2::-1]:
        acc *= p
        acc += c
    return acc


def _turn_integrals(phi: np.ndarray):
    """Real and imaginary parts of ``E1 = int_0^1 e^{i phi s} ds`` and ``E2 = int_0^1 s e^{i phi s} ds``.

    For ``|phi| <= 0.6`` (every Dubins4D branch of the paper's tree: ``0.25 rad/s x 2 s``) a
    7-term power series, accurate to rounding and about 5x cheaper than trigonometry.  Larger
    angles use the closed forms, written with ``1 - cos(phi) = 2 sin^2(phi/2)`` so that nothing
    cancels badly.  Returns ``(e1r, e1i, e2r, e2i)``.
    """
    phi = np.asarray(phi, dtype=float)
    small = np.abs(phi) <= _SERIES_MAX
    if small.all():
        p = phi * phi
        c1r, c1i, c2r, c2i = _COEF
        return _horner(p, c1r), phi * _horner(p, c1i), _horner(p, c2r), phi * _horner(p, c2i)
    out = list(_closed_turn_integrals(np.where(small, 1.0, phi)))
    if small.any():
        ser = _turn_integrals(phi[small])
        for o, v in zip(out, ser, strict=True):
            o[small] = v
    return tuple(out)


def _closed_turn_integrals(phi):
    """The closed forms of :func:`_turn_integrals` (``phi != 0``; arrays or floats)."""
    sn, cs = np.sin(phi), np.cos(phi)
    h = np.sin(0.5 * phi)
    one_m_cos = 2.0 * h * h
    inv = 1.0 / phi
    return sn * inv, one_m_cos * inv, (phi * sn - one_m_cos) * inv * inv, (sn - phi * cs) * inv * inv


def _displace(x0, y0, th0, v0, a, t, e1r, e1i, e2r, e2i):
    """Position after ``t`` seconds from the turn integrals of ``w t`` (arrays or floats)."""
    c0, s0 = np.cos(th0), np.sin(th0)
    lin = v0 * t
    quad = a * t * t
    re = lin * e1r + quad * e2r
    im = lin * e1i + quad * e2i
    return x0 + c0 * re - s0 * im, y0 + s0 * re + c0 * im


def _segment(x0, y0, th0, v0, w, a, t):
    """Displacement after ``t`` seconds of constant turn rate ``w`` and acceleration ``a``."""
    e1r, e1i, e2r, e2i = _turn_integrals(w * t)
    return _displace(x0, y0, th0, v0, a, t, e1r, e1i, e2r, e2i)


def _horner_1(p, coef, r):
    """Scalar :func:`_horner` of coefficient row ``r``."""
    acc = coef[r, coef.shape[1] - 1]
    for j in range(coef.shape[1] - 2, -1, -1):
        acc *= p
        acc += coef[r, j]
    return acc


def _turn_integrals_1(phi, coef):
    """Scalar :func:`_turn_integrals` (same operations, same order; no array allocated)."""
    if abs(phi) <= _SERIES_MAX:
        p = phi * phi
        return _horner_1(p, coef, 0), phi * _horner_1(p, coef, 1), _horner_1(p, coef, 2), phi * _horner_1(p, coef, 3)
    return _closed_1(phi)


def segment_position(x0, y0, th0, v0, w, a, t, coef):
    """Position ``(x, y)`` after holding turn rate ``w`` and acceleration ``a`` for ``t`` s from
    ``(x0, y0, th0, v0)``, without speed bounds (compiled; ``coef``: :data:`SERIES_COEFFICIENTS`)."""
    e1r, e1i, e2r, e2i = _turn_integrals_1(w * t, coef)
    return _displace_1(x0, y0, th0, v0, a, t, e1r, e1i, e2r, e2i)


def _clamped_start(v0, w, a, t_end, lo, hi):
    """The start of a held control: speed and controls clamped to their bounds (``lo``/``hi``:
    (v, u1, u2) bounds), and whether/when the speed saturates within ``t_end``."""
    v0 = min(max(v0, lo[0]), hi[0])
    w = min(max(w, lo[1]), hi[1])
    a = min(max(a, lo[2]), hi[2])
    v_end = v0 + a * t_end
    sat = v_end > hi[0] or v_end < lo[0]
    t_sat = ((hi[0] - v0) / a if a > 0 else (lo[0] - v0) / a) if sat else 0.0
    return v0, w, a, sat, t_sat


def _state_at_1(x0, y0, th0, v0, w, a, t, sat, t_sat, lo, hi, coef):
    """The state at time ``t`` of a held control from a clamped start (:func:`_clamped_start`)."""
    th = th0 + w * t
    if not sat:
        x, y = segment_position(x0, y0, th0, v0, w, a, t, coef)
        return x, y, th, v0 + a * t
    t1 = min(t, max(t_sat, 0.0))
    x1, y1 = segment_position(x0, y0, th0, v0, w, a, t1, coef)
    v1 = min(max(v0 + a * t1, lo[0]), hi[0])
    th1 = th0 + w * t1
    x, y = segment_position(x1, y1, th1, v1, w, 0.0, t - t1, coef)
    return x, y, th, v1


def _states_at_loop(states, controls, times, lo, hi, coef, out):
    """:meth:`Dubins4D.states_at` one state at a time; ``lo``/``hi``: (v, u1, u2) bounds."""
    t_end = 0.0
    for k in range(times.shape[0]):
        t_end = max(t_end, times[k])
    for n in range(states.shape[0]):
        v0, w, a, sat, t_sat = _clamped_start(states[n, 3], controls[n, 0], controls[n, 1], t_end, lo, hi)
        for k in range(times.shape[0]):
            out[n, k, 0], out[n, k, 1], out[n, k, 2], out[n, k, 3] = _state_at_1(
                states[n, 0], states[n, 1], states[n, 2], v0, w, a, times[k], sat, t_sat, lo, hi, coef
            )
    return out


def _state_after_1(x0, y0, th0, v0, w, a, t, lo, hi, coef):
    """:func:`_states_at_loop` for one state and the one time ``t`` (scalars in and out)."""
    v0, w, a, sat, t_sat = _clamped_start(v0, w, a, t, lo, hi)
    return _state_at_1(x0, y0, th0, v0, w, a, t, sat, t_sat, lo, hi, coef)


#: The series coefficients of the turn integrals as one (4, 7) array: the argument ``coef`` of the
#: compiled path kernels (here and :func:`rmm_envs.systems.maze.maze_kernels.dubins_path`).
SERIES_COEFFICIENTS = np.array(_COEF)
if njit is not None:  # the scalar path compiles the same closed forms and displacement as numpy's
    _closed_1 = njit(cache=True)(_closed_turn_integrals)
    _displace_1 = njit(cache=True)(_displace)
    _horner_1 = njit(cache=True)(_horner_1)
    _turn_integrals_1 = njit(cache=True)(_turn_integrals_1)
    segment_position = njit(cache=True)(segment_position)
    _clamped_start = njit(cache=True)(_clamped_start)
    _state_at_1 = njit(cache=True)(_state_at_1)
    _states_at_compiled = njit(cache=True)(_states_at_loop)
    _state_after_compiled = njit(cache=True)(_state_after_1)
else:  # pragma: no cover
    _states_at_compiled = None
    _state_after_compiled = None


class FullBraking(SafeDefault):
    """Dubins4D's safe default: full braking (the acceleration at its lower bound) with a turn
    rate held for the episode, ``turn="random"`` (default, as the paper's code: drawn uniformly
    over the turn-rate bounds once per episode) or ``"zero"`` (the paper's text)."""

    description = "full braking with a constant turn rate"
    options = ("turn",)

    def policy(self, space, rng: np.random.Generator, turn: str = "random", **options):
        self.check_options(options)
        if turn not in ("random", "zero"):
            raise ValueError(f"turn must be 'random' or 'zero', got {turn!r}")
        lo, hi = float(space.control_low[0]), float(space.control_high[0])
        control = space.control_low.copy()
        control[0] = float(rng.uniform(lo, hi)) if turn == "random" else min(max(0.0, lo), hi)
        return lambda observation: control


@dataclass(frozen=True)
class Dubins4D:
    """Batched Dubins4D dynamics with speed and control bounds.

    The speed clamp is the one the paper's environment applies inside its ODE right-hand side;
    the original's *risk sampler* had it removed (docs/original-code.md, item 5), we keep it
    everywhere, so sampled branches obey the environment's limits.  Propagation is exact for a
    held control: the speed is piecewise linear in time (accelerate until a speed bound, then
    hold), the heading linear, and the position the closed-form integral
    ``int_0^T (v0 + a s) exp(i (th0 + w s)) ds`` in real arithmetic (a power series where
    ``|w T| <= 0.6``, closed forms beyond), so straight and turning motion are both exact to
    rounding.  Large batches (risk labels) run as numpy array code; a handful of states (an env
    step) run through the same formulas compiled with numba, where numpy's per-call overhead
    would dominate (about 40 us against 3 us for one 16-point path; both agree to rounding, tested).

    Args:
        v_min, v_max: speed bounds in m/s (default 0 and 2).
        u1_min, u1_max: turn-rate bounds in rad/s (default -0.25, 0.25).
        u2_min, u2_max: acceleration bounds in m/s^2 (default -0.5, 0.5).
    """

    v_min: float = 0.0
    v_max: float = 2.0
    u1_min: float = -0.25
    u1_max: float = 0.25
    u2_min: float = -0.5
    u2_max: float = 0.5

    state_dim: int = 4
    control_dim: int = 2
    # the compiled loop's (v, u1, u2) bounds, set by __post_init__ (not arguments, not compared)
    _lo: np.ndarray = field(init=False, repr=False, compare=False)
    _hi: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (self.v_min < self.v_max):
            raise ValueError(f"v_min ({self.v_min}) must be below v_max ({self.v_max})")
        if not (self.u1_min <= self.u1_max) or not (self.u2_min <= self.u2_max):
            raise ValueError(
                f"control bounds must satisfy min <= max, got u1 in [{self.u1_min}, {self.u1_max}]"
                f" and u2 in [{self.u2_min}, {self.u2_max}]"
            )
        # the compiled loop's (v, u1, u2) bounds, built once: it runs at every guardian decision
        for name, arr in (
            ("_lo", [self.v_min, self.u1_min, self.u2_min]),
            ("_hi", [self.v_max, self.u1_max, self.u2_max]),
        ):
            object.__setattr__(self, name, np.array(arr, dtype=float))

    @property
    def control_low(self) -> np.ndarray:
        return np.array([self.u1_min, self.u2_min])

    @property
    def control_high(self) -> np.ndarray:
        return np.array([self.u1_max, self.u2_max])

    def clip_controls(self, controls: np.ndarray) -> np.ndarray:
        return np.clip(controls, self.control_low, self.control_high)

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` controls uniform over the control box, shape ``(n, 2)``."""
        return rng.uniform(self.control_low, self.control_high, size=(n, 2))

    def propagate(self, states: np.ndarray, controls: np.ndarray, duration: float, n_steps: int) -> np.ndarray:
        """Exact path under a zero-order-hold control.

        Args:
            states: ``(N, 4)`` initial states ``(x, y, theta, v)``; speeds outside the bounds
                are first clipped into them.
            controls: ``(N, 2)`` controls ``(u1, u2)``, clipped to the control box.
            duration: how long the control is held, seconds (``>= 0``).
            n_steps: number of equally spaced path points, ``>= 2`` (the first is the start).

        Returns:
            ``(N, n_steps, 4)`` path; heading is *not* wrapped (it is continuous along a path).
        """
        states = np.asarray(states, dtype=float)
        controls = np.asarray(controls, dtype=float)
        if states.ndim != 2 or states.shape[1] != 4:
            raise ValueError(f"states must have shape (N, 4), got {states.shape}")
        if controls.shape != (states.shape[0], 2):
            raise ValueError(f"controls must have shape ({states.shape[0]}, 2) to match states, got {controls.shape}")
        if not np.isfinite(duration) or duration < 0:
            raise ValueError(f"duration must be a finite number >= 0, got {duration}")
        if int(n_steps) != n_steps or n_steps < 2:
            raise ValueError(f"n_steps must be an integer >= 2, got {n_steps}")
        times = np.linspace(0.0, float(duration), int(n_steps))
        return self.states_at(states, controls, times)

    def states_at(
        self, states: np.ndarray, controls: np.ndarray, times: np.ndarray, compiled: bool | None = None
    ) -> np.ndarray:
        """States at each of ``times`` (shape ``(T,)``, all ``>= 0``): ``(N, T, 4)``.

        ``compiled``: ``None`` picks the faster path for ``N``; ``True`` always runs the compiled
        loop, whose result for one state does not depend on ``N`` (the vector environment relies
        on that to match the single one bit for bit).
        """
        if (compiled or (compiled is None and states.shape[0] <= _COMPILED_MAX_N)) and _states_at_compiled is not None:
            out = np.empty((states.shape[0], len(times), 4))
            return _states_at_compiled(
                np.ascontiguousarray(states, dtype=float),
                np.ascontiguousarray(controls, dtype=float),
                np.asarray(times, dtype=float),
                self._lo,
                self._hi,
                SERIES_COEFFICIENTS,
                out,
            )
        return self._states_at_numpy(states, controls, times)

    def state_after(self, state, control, t: float) -> np.ndarray:
        """The state ``(4,)`` after holding ``control`` for ``t >= 0`` seconds from ``state``:
        :meth:`states_at` for one state and one time, through the compiled loop (the same
        floats as ``states_at(state[None], control[None], [t], compiled=True)[0, 0]``), with
        the least per-call work: a guardian predicts one state per decision."""
        if _state_after_compiled is None:  # pragma: no cover - numba is a dependency
            return self._states_at_numpy(
                np.asarray(state, float).reshape(1, 4), np.asarray(control, float).reshape(1, 2), np.array([float(t)])
            )[0, 0]
        x, y, th, v = np.asarray(state, dtype=float).tolist()
        w, a = np.asarray(control, dtype=float).tolist()
        return np.array(_state_after_compiled(x, y, th, v, w, a, float(t), self._lo, self._hi, SERIES_COEFFICIENTS))

    def _states_at_numpy(self, states: np.ndarray, controls: np.ndarray, times: np.ndarray) -> np.ndarray:
        x0, y0, th0 = states[:, 0:1], states[:, 1:2], states[:, 2:3]
        v0 = np.clip(states[:, 3:4], self.v_min, self.v_max)
        u = np.clip(controls, self.control_low, self.control_high)
        w, a = u[:, 0:1], u[:, 1:2]
        t = np.asarray(times, dtype=float)[None, :]
        out = np.empty((states.shape[0], t.shape[1], 4))
        out[..., 2] = th0 + w * t

        # speed saturation: accelerate until a bound, then hold the speed.  Only the branches
        # that reach a bound within the horizon need the two-phase solution.
        t_end = float(t.max()) if t.size else 0.0
        v_end = v0[:, 0] + a[:, 0] * t_end
        sat = (v_end > self.v_max) | (v_end < self.v_min)
        out[..., 0], out[..., 1] = _segment(x0, y0, th0, v0, w, a, t)
        out[..., 3] = v0 + a * t
        if not sat.any():
            return out
        x0, y0, th0, v0, w, a = x0[sat], y0[sat], th0[sat], v0[sat], w[sat], a[sat]
        t_sat = np.where(a > 0, (self.v_max - v0) / a, (self.v_min - v0) / a)
        t1 = np.minimum(t, np.maximum(t_sat, 0.0))
        x1, y1 = _segment(x0, y0, th0, v0, w, a, t1)
        v1 = np.clip(v0 + a * t1, self.v_min, self.v_max)
        th1 = th0 + w * t1
        block = np.empty((x0.shape[0], t.shape[1], 4))
        block[..., 0], block[..., 1] = _segment(x1, y1, th1, v1, w, 0.0, t - t1)
        block[..., 2] = th0 + w * t
        block[..., 3] = v1
        out[sat] = block
        return out


#: the guardian action's control fields of ``u = (u1, u2)``, in order (the Dubins4D envs' action space)
CONTROLS = ("turnrate_ctrl", "accel_ctrl")
#: the name of these dynamics in its guardian action space's contract (rmm_envs.autonomy.SystemContract)
DYNAMICS_NAME = "dubins4d"


def desired_heading(theta: float, theta_goal: float) -> float:
    """The original's literal branch-cut heuristic for the target heading."""
    if -math.pi < theta < 0 and math.pi + theta <= theta_goal <= math.pi:
        return -1.5 * math.pi
    if 0 < theta < math.pi and -math.pi <= theta_goal <= -math.pi + theta:
        return 1.5 * math.pi
    return theta_goal


#: :func:`desired_heading` compiled once (numba; the Python function without it): the driver's
#: CLF rows and the cbf guardian's rows call it from their compiled loops
desired_heading_compiled = njit(cache=True)(desired_heading) if njit is not None else desired_heading
