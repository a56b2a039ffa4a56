"""Rating the driver's own control with an LRMM model, from the local observation alone.

The ``lrmm`` guardian's ``trigger="driver"`` (the quadrotor) rates the driver's next control,
``info["nominal_control"]``, by the model's state risk of the observation *predicted* after
holding it for the head's hold time (a velocity command replaces the measured velocity, an
acceleration changes the speed, a turn rate turns the heading and the rays; the position does
not move).  **When** (:func:`driver_at_risk`): in control while that rating is above the
threshold and the head's best candidate, or holding still, is rated materially lower; it stays
while the rating is above the threshold, then ``commit`` steps.  **What** (:class:`Slide`): the
variant of the driver's control nearest to it rated at or below the threshold (climbing at its
horizontal velocity, half of it or none), else the head's safest candidate.

Offers :func:`make_rater`, :class:`PredictRater`, :func:`driver_control`, :func:`driver_at_risk`,
:class:`Slide` and :func:`hand_back_options`.  The prediction's stated error, why this rule and
the alternatives tried with their figures: docs/design-notes.md#rmm_guardianslrmmnominal.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence

import numpy as np

from rmm_envs.portable import wrap_angle

__all__ = [
    "SLIDE_MOVES",
    "TRIGGERS",
    "VELOCITY_CONTROLS",
    "PredictRater",
    "Slide",
    "driver_at_risk",
    "driver_control",
    "hand_back_options",
    "make_rater",
]

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
            old = [float(v) for v in x[r0 : r0 + n]]
            for k in range(n):
                f = k + shift
                lo_k = math.floor(f)
                w = f - lo_k
                y[r0 + k] = (1.0 - w) * old[lo_k % n] + w * old[(lo_k + 1) % n]
        return y

    def rate_many(self, controls, model, x) -> list[float]:
        """The model's state risk of ``x`` predicted after each of ``controls``; ``ValueError``
        naming the controls when a risk is not finite (NaN would compare as "safe")."""
        rows = np.stack([self.predict(x, u) for u in controls])
        rated = [float(v) for v in model.predict_all(rows)[:, 0]]
        if not all(map(math.isfinite, rated)):
            raise ValueError(
                f"the LRMM model rated the controls {[list(u) for u in controls]} with non-finite risks {rated}"
            )
        return rated


#: the slide's variants of the driver's velocity command: (cos, sin) of the turn of its horizontal
#: velocity, the fraction of that velocity kept, and the vertical velocity: ``"climb"`` (the box's
#: largest) or the fraction of the driver's kept
SLIDE_MOVES = (((1.0, 0.0), 1.0, "climb"), ((1.0, 0.0), 0.5, "climb"), ((1.0, 0.0), 0.0, "climb"))


class Slide:
    """The driver's own velocity command bent around what the model rates risky (``slide``).

    The variants of the driver's command ``u`` (forward, left, up velocity and the rest, in the
    action space's order) are :data:`SLIDE_MOVES`; every other control (the yaw rate) is the
    driver's.  ``u`` itself is not one of them: a slide is applied only while the guardian is in
    control.  They are ordered by how far they are from ``u`` (Euclidean over the velocities),
    the order of :data:`SLIDE_MOVES` on ties; :meth:`choose` rates them as ``u`` is rated and
    returns the first one rated at or below the threshold, ``None`` when none is.

    Args:
        controls: the action space's control fields (``vforward_ctrl``, ``vleft_ctrl`` and
            ``vup_ctrl`` needed).
        low, high: the action space's control bounds (variants are clipped to them).
        moves: ``(turn, kept, vertical)`` triples as in :data:`SLIDE_MOVES` (default: those).
    """

    def __init__(self, controls, low, high, moves=None) -> None:
        controls = tuple(controls)
        if any(c not in controls for c in VELOCITY_CONTROLS):
            raise ValueError(
                f"slide bends a velocity command: it needs the controls {tuple(VELOCITY_CONTROLS)}, got {controls}"
            )
        self.f, self.l, self.up = (controls.index(c) for c in VELOCITY_CONTROLS)
        self.low, self.high = [float(v) for v in low], [float(v) for v in high]
        self.moves = SLIDE_MOVES if moves is None else moves

    def variants(self, u) -> list[list[float]]:
        """The variants of ``u``, nearest first (class docstring)."""
        u = [float(v) for v in u]
        out = []
        for (c, s), k, z in self.moves:
            v = list(u)
            v[self.f] = k * (c * u[self.f] - s * u[self.l])
            v[self.l] = k * (s * u[self.f] + c * u[self.l])
            v[self.up] = self.high[self.up] if z == "climb" else z * u[self.up]
            v = [min(max(a, lo), hi) for a, lo, hi in zip(v, self.low, self.high, strict=True)]
            if v != u and v not in out:
                out.append(v)
        gap = [math.sqrt(sum((v[j] - u[j]) ** 2 for j in (self.f, self.l, self.up))) for v in out]
        return [out[i] for i in sorted(range(len(out)), key=lambda i: gap[i])]

    def choose(self, rater: PredictRater, model, x, u, threshold: float) -> list | None:
        """The nearest variant of ``u`` rated at or below ``threshold``; ``None`` if none is."""
        options = self.variants(u)
        if not options:
            return None
        rated = rater.rate_many(options, model, x)
        return next((v for v, r in zip(options, rated, strict=True) if r <= threshold), None)


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
                f"lrmm: trigger 'driver' rates the driver's control, info['nominal_control'], and this env "
                f"gives none (info: {keys!r}); using the state risk (trigger 'risk') instead",
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


def hand_back_options(
    trigger, margin, restart, stored: dict | None, action: str, hysteresis: bool, slide=None, still=None, stay=None
) -> tuple:
    """``lrmm``'s ``(trigger, margin, restart, slide, still, stay)``: each given one, else the model
    file's stored decision (used only with ``action="head"`` and, for the trigger, without
    hysteresis: a file's defaults are for its own rule), else ``"risk"``, 0, 0, False, None, True;
    ``ValueError`` naming a bad value or a given combination that cannot work (both rate or
    accelerate with the head's candidates; ``slide``, ``still`` and ``stay=False`` change how the
    driver's control is judged, so they need ``trigger="driver"``)."""
    stored = dict(stored or {}) if action == "head" else {}
    if hysteresis:
        stored.pop("trigger", None)
    trigger = trigger if trigger is not None else stored.get("trigger", "risk")
    if trigger not in TRIGGERS:
        raise ValueError(f"trigger must be one of {TRIGGERS}, got {trigger!r}")
    if trigger == "driver" and (action != "head" or hysteresis):
        raise ValueError(
            f"trigger='driver' compares the driver's control with the head's candidates: it needs "
            f"action='head' without hysteresis, got action={action!r}, hysteresis={hysteresis!r}"
        )
    values: list[float | None] = []
    for name, given, default in (("margin", margin, 0.0), ("restart", restart, 0.0), ("still", still, None)):
        value = given if given is not None else stored.get(name, default)
        if value is None:
            values.append(None)
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < math.inf:
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        values.append(float(value))
    assert values[1] is not None  # restart defaults to 0.0 (set_decision stores no None)
    if values[1] > 0 and action != "head":
        raise ValueError(f"restart accelerates with the head's candidates: it needs action='head', got {action!r}")
    flags = []
    for name, given, default in (("slide", slide, False), ("stay", stay, True)):
        value = given if given is not None else stored.get(name, default)
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {value!r}")
        flags.append(bool(value))
    if trigger != "driver" and (flags[0] or values[2] is not None or not flags[1]):
        raise ValueError(
            f"slide, still and stay=False judge the driver's control, info['nominal_control']: they need "
            f"trigger='driver', got {trigger!r}"
        )
    margin, restart, still = values
    return trigger, margin, restart, flags[0], still, flags[1]


def driver_at_risk(rated, threshold: float, margin: float, still: float | None = None, holding: bool = False) -> bool:
    """Whether ``lrmm`` (``trigger="driver"``) is to be in control this step, from ``rated``: the
    driver's control, the zero control (holding still) and the head's candidates, each rated by
    :meth:`PredictRater.rate_many`.  Never at or below ``threshold``; above it, while ``holding``
    (in control, with ``stay``), when the best candidate is rated more than ``margin`` lower, or
    (with ``still``) when the zero control is rated more than ``still`` lower."""
    u, zero, best = rated[0], rated[1], min(rated[2:])
    if u <= threshold:
        return False
    return holding or u - best > margin or (still is not None and u - zero > still)
