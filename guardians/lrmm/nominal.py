"""Rating the driver's own control with an LRMM model, from the local observation alone.

:class:`PredictRater` rates a control by the model's state risk of the observation *predicted*
after holding it for the head's hold time (a velocity command replaces the measured velocity,
an acceleration changes the speed, a turn rate turns the heading and the rays; the position
does not move).  :func:`driver_at_risk` is :class:`~rmm_guardians.lrmm.strategies.RatedDriver`'s
test; :func:`driver_control` reads the driver's control from ``info["nominal_control"]``.
Offers :func:`make_rater`, :class:`PredictRater`, :func:`driver_control` and
:func:`driver_at_risk`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np
from numba import njit

from rmm_envs.machine_independent import wrap_angle

__all__ = ["VELOCITY_CONTROLS", "PredictRater", "driver_at_risk", "driver_control", "make_rater"]

#: control field -> component of the observation's ``"velocity"`` field that measures it
VELOCITY_CONTROLS = {"vforward_ctrl": 0, "vleft_ctrl": 1, "vup_ctrl": 2}


class PredictRater:
    """The model's state risk (unit 0) of the observation predicted after holding a control.

    Args:
        layout: the observation's :class:`~rmm_envs.autonomy.ObservationLayout`.
        controls: the action space's control fields, in order.
        hold: seconds the control is held (the head's ``candidate_hold``).
        low, high: the observation space's bounds (the predicted speed is clipped to them).
    """

    def __init__(self, layout, controls: Sequence[str], hold: float, low, high) -> None:
        self.hold = float(hold)
        self.velocity = [
            (j, layout["velocity"].start + VELOCITY_CONTROLS[c])
            for j, c in enumerate(controls)
            if c in VELOCITY_CONTROLS and "velocity" in layout
        ]
        self.accel = self.turn = None
        if "accel_ctrl" in controls and "speed" in layout:
            i = layout.index("speed")
            self.accel = (controls.index("accel_ctrl"), i, float(low[i]), float(high[i]))
        n = layout.size_of("rays") if "rays" in layout else 0
        even = n > 0 and all(
            abs(float(wrap_angle(a - 2.0 * math.pi * k / n))) < 1e-9 for k, a in enumerate(layout.ray_angles)
        )
        if "turnrate_ctrl" in controls and "heading" in layout and even:
            self.turn = (controls.index("turnrate_ctrl"), layout.index("heading"), layout["rays"].start, n)
        # the same as integers and bounds for the compiled prediction (-1: not predicted)
        accel, turn = self.accel or (-1, -1, 0.0, 0.0), self.turn or (-1, -1, 0, 0)
        self._kernel_args = (
            np.array([j for j, _ in self.velocity], dtype=np.int64),
            np.array([i for _, i in self.velocity], dtype=np.int64),
            np.array([accel[0], accel[1], turn[0], turn[1], turn[2], turn[3]], dtype=np.int64),
            np.array([accel[2], accel[3]], dtype=float),
        )

    @property
    def applies(self) -> bool:
        return bool(self.velocity) or self.accel is not None or self.turn is not None

    def predict(self, x, u) -> np.ndarray:
        """The observation ``x`` as predicted after holding control ``u`` for ``hold`` seconds."""
        return self.predict_many(x, [u])[0]

    def predict_many(self, x, controls) -> np.ndarray:
        """The observation ``x`` as predicted after holding each of ``controls`` (``(K, c)``) for
        ``hold`` seconds, one row each: a velocity command replaces the measured velocity (the loop
        tracks it within a fraction of a second), an acceleration changes the speed within its
        bounds, a turn rate turns the heading, and the ray at angle ``a`` after the turn reads what
        the ray at ``a + delta`` read before it (linear between neighbours).  One compiled call
        (:func:`_predict_rows`): a rated decision predicts eight observations each step."""
        u = np.ascontiguousarray(np.asarray(controls, dtype=float).reshape(len(controls), -1))
        return _predict_rows(np.ascontiguousarray(x, dtype=float), u, self._kernel_args, self.hold)

    def rate_many(self, controls, model, x) -> list[float]:
        """The model's state risk of ``x`` predicted after each of ``controls``; ``ValueError``
        naming the controls when a risk is not finite (NaN would compare as "safe")."""
        rows = self.predict_many(x, controls)
        rated = [float(v) for v in model.predict_all(rows)[:, 0]]
        if not all(map(math.isfinite, rated)):
            raise ValueError(
                f"the LRMM model rated the controls {[list(u) for u in controls]} with non-finite risks {rated}"
            )
        return rated


def _predict_rows(x, u, args, hold):  # pragma: no cover - compiled
    """:meth:`PredictRater.predict_many`'s rows, element by element with numpy's operations in
    its order (the same bits: tests/test_lrmm_filter.py checks them against plain Python)."""
    vel_j, vel_i, idx, bounds = args
    aj, ai, tj, th, r0, n = idx[0], idx[1], idx[2], idx[3], idx[4], idx[5]
    two_pi = 2.0 * math.pi
    y = np.empty((u.shape[0], x.shape[0]))
    for k in range(u.shape[0]):
        for d in range(x.shape[0]):
            y[k, d] = x[d]
        for t in range(vel_j.shape[0]):
            y[k, vel_i[t]] = u[k, vel_j[t]]
        if aj >= 0:
            v = y[k, ai] + u[k, aj] * hold
            v = bounds[0] if v < bounds[0] else v  # np.maximum, then np.minimum (NaN stays NaN)
            y[k, ai] = bounds[1] if v > bounds[1] else v
        if tj >= 0:
            delta = u[k, tj] * hold
            y[k, th] = (y[k, th] + delta + math.pi) % two_pi - math.pi  # wrap_angle(heading + delta)
            shift = delta * n / two_pi
            for r in range(n):
                f = r + shift
                lo = math.floor(f)
                w = f - lo
                k0 = int(lo) % n
                y[k, r0 + r] = (1.0 - w) * x[r0 + k0] + w * x[r0 + (k0 + 1) % n]
    return y


_predict_rows = njit(cache=True)(_predict_rows)


def make_rater(controls: Sequence[str], layout, hold, low, high) -> PredictRater | None:
    """The rater for this env, or ``None`` when the observation measures none of the controls'
    effects (no ``layout``, or none of the fields :class:`PredictRater` predicts)."""
    if layout is None or hold is None:
        return None
    rater = PredictRater(layout, tuple(controls), hold, low, high)
    return rater if rater.applies else None


def driver_control(info, action_space, warn: bool = True) -> list | None:
    """The driver's control this step, ``info["nominal_control"]``, as a list in the action
    space's control order.  ``None`` when ``info`` has none (with a ``UserWarning`` naming the key
    if ``warn``); ``ValueError`` naming the value when it is not ``control_dim`` finite numbers."""
    u = info.get("nominal_control") if isinstance(info, dict) else None
    if u is None:
        if warn:
            keys = sorted(info) if isinstance(info, dict) else info
            warnings.warn(
                f"lrmm: strategies RatedDriver and Slide read the driver's control, info['nominal_control'], and this env "
                f"gives none (info: {keys!r}); using the state risk instead",
                UserWarning,
                stacklevel=4,
            )
        return None
    try:
        n = np.asarray(u, dtype=float).reshape(-1) if np.ndim(u) <= 1 else np.empty(0)
    except (TypeError, ValueError):  # not numbers
        n = np.empty(0)
    if n.shape[0] != action_space.control_dim or not np.all(np.isfinite(n)):
        raise ValueError(
            f"info['nominal_control'] must be {action_space.control_dim} finite numbers "
            f"{action_space.controls}, got {u!r}"
        )
    return n.tolist()


def driver_at_risk(rated, threshold: float, margin: float, still: float | None = None, holding: bool = False) -> bool:
    """Whether :class:`~rmm_guardians.lrmm.strategies.RatedDriver` puts ``lrmm`` in control this step, from ``rated``: the
    driver's control, the zero control (holding still) and the head's candidates, each rated by
    :meth:`PredictRater.rate_many`.  Never at or below ``threshold``; above it, while ``holding``
    (in control, with ``stay``), when the best candidate is rated more than ``margin`` lower, or
    (with ``still``) when the zero control is rated more than ``still`` lower."""
    u, zero, best = rated[0], rated[1], min(rated[2:])
    if u <= threshold:
        return False
    return holding or u - best > margin or (still is not None and u - zero > still)
