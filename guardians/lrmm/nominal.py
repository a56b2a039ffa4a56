"""Rating the driver's own control with an LRMM model, from the local observation alone.

The ``lrmm`` guardian's ``trigger="driver"`` (see :mod:`guardians.lrmm.guardian`) asks how risky
the driver's next control is, ``info["nominal_control"]``, and how much risk the head's safest
candidate would save.  The head rates only its fixed candidates, so both are rated here the same
way: the model's state risk (unit 0) of the observation *predicted* after holding the control
for the head's hold time (``candidate_hold``, 1 s for the shipped models), a cheap one-step
prediction that moves only what the observation measures of the control's effect:

* a velocity command (``vforward_ctrl``, ``vleft_ctrl``, ``vup_ctrl``: the quadrotor) replaces
  the measured heading-frame ``"velocity"`` (the stabilising controller tracks a command within
  a fraction of a second);
* an acceleration (``accel_ctrl``: Dubins4D) changes the ``"speed"`` by ``a * hold``, clipped
  to the observation space's bounds;
* a turn rate (``turnrate_ctrl``) turns the ``"heading"`` by ``w * hold`` (wrapped to
  ``[-pi, pi)``) and the rays with it, when they are evenly spaced over the full circle from the
  heading: the ray at angle ``a`` then reads what the ray at ``a + w * hold`` read, linearly
  interpolated between the two nearest rays.

A yaw rate is not predicted (the quadrotor's rays turn with the body, but its rater leaves
them).  The position does not move: the rays keep their lengths apart from the turn.  That is the
prediction's stated error; it rates a control by the state it leads to *here*, which is what
separates "keep flying at the wall" from "stop" or "back off" for a risk model of random futures.
"""

from __future__ import annotations

import math
import warnings
from typing import Sequence

import numpy as np

from rmm_envs.portable import wrap_angle

__all__ = ["TRIGGERS", "VELOCITY_CONTROLS", "PredictRater", "driver_control", "hand_back_options", "make_rater"]

TRIGGERS = ("risk", "driver")  # when lrmm takes control: the state risk, or the driver's control rated

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
        self.velocity = [(j, layout["velocity"].start + VELOCITY_CONTROLS[c]) for j, c in enumerate(controls)
                         if c in VELOCITY_CONTROLS and "velocity" in layout]
        self.accel = self.turn = None
        if "accel_ctrl" in controls and "speed" in layout:
            i = layout.index("speed")
            self.accel = (controls.index("accel_ctrl"), i, float(low[i]), float(high[i]))
        n = layout.size_of("rays") if "rays" in layout else 0
        even = n > 0 and all(abs(float(wrap_angle(a - 2.0 * math.pi * k / n))) < 1e-9 for k, a in enumerate(layout.ray_angles))
        if "turnrate_ctrl" in controls and "heading" in layout and even:
            self.turn = (controls.index("turnrate_ctrl"), layout.index("heading"), layout["rays"].start, n)

    @property
    def applies(self) -> bool:
        return bool(self.velocity) or self.accel is not None or self.turn is not None

    def predict(self, x, u) -> np.ndarray:
        """The observation ``x`` as predicted after holding control ``u`` for ``hold`` seconds."""
        y = np.array(x, dtype=float)
        for j, i in self.velocity:  # the velocity loop tracks the command within a fraction of a second
            y[i] = u[j]
        if self.accel is not None:
            j, i, lo, hi = self.accel
            y[i] = min(max(y[i] + u[j] * self.hold, lo), hi)
        if self.turn is not None:
            j, h, r0, n = self.turn
            delta = u[j] * self.hold
            y[h] = float(wrap_angle(y[h] + delta))
            # the ray at angle a after the turn reads what the ray at a + delta read before it
            shift = delta * n / (2.0 * math.pi)
            old = [float(v) for v in x[r0:r0 + n]]
            for k in range(n):
                f = k + shift
                lo_k = math.floor(f)
                w = f - lo_k
                y[r0 + k] = (1.0 - w) * old[lo_k % n] + w * old[(lo_k + 1) % n]
        return y

    def rate_many(self, controls, model, x) -> list[float]:
        rows = np.stack([self.predict(x, u) for u in controls])
        return [float(v) for v in model.predict_all(rows)[:, 0]]


def make_rater(controls: Sequence[str], layout, hold, low, high) -> "PredictRater | None":
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
            warnings.warn(f"lrmm: trigger 'driver' rates the driver's control, info['nominal_control'], and this env "
                          f"gives none (info: {keys!r}); using the state risk (trigger 'risk') instead", UserWarning,
                          stacklevel=4)
        return None
    try:
        n = np.asarray(u, dtype=float).reshape(-1) if np.ndim(u) <= 1 else np.empty(0)
    except (TypeError, ValueError):  # not numbers
        n = np.empty(0)
    if n.shape[0] != action_space.control_dim or not np.all(np.isfinite(n)):
        raise ValueError(f"info['nominal_control'] must be {action_space.control_dim} finite numbers "
                         f"{action_space.controls}, got {u!r}")
    return n.tolist()


def hand_back_options(trigger, margin, restart, stored: dict | None, action: str, hysteresis: bool) -> tuple:
    """``lrmm``'s ``(trigger, margin, restart)``: each given one, else the model file's stored
    decision (used only with ``action="head"`` and, for the trigger, without hysteresis: a file's
    defaults are for its own rule), else ``"risk"``, 0, 0; ``ValueError`` naming a bad value or a
    given combination that cannot work (both rate or accelerate with the head's candidates)."""
    stored = dict(stored or {}) if action == "head" else {}
    if hysteresis:
        stored.pop("trigger", None)
    trigger = trigger if trigger is not None else stored.get("trigger", "risk")
    if trigger not in TRIGGERS:
        raise ValueError(f"trigger must be one of {TRIGGERS}, got {trigger!r}")
    if trigger == "driver" and (action != "head" or hysteresis):
        raise ValueError(f"trigger='driver' compares the driver's control with the head's candidates: it needs "
                         f"action='head' without hysteresis, got action={action!r}, hysteresis={hysteresis!r}")
    values = []
    for name, given in (("margin", margin), ("restart", restart)):
        value = given if given is not None else stored.get(name, 0.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < math.inf:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        values.append(float(value))
    if values[1] > 0 and action != "head":
        raise ValueError(f"restart accelerates with the head's candidates: it needs action='head', got {action!r}")
    return (trigger, *values)
