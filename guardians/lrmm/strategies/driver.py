"""Strategies that read the driver's control and rate it with the model
(:mod:`rmm_guardians.lrmm.nominal`): :class:`RatedDriver` (when) and :class:`Slide` (what)."""

from __future__ import annotations

import math

import numpy as np

from rmm_guardians.lrmm.nominal import VELOCITY_CONTROLS, driver_at_risk, make_rater
from rmm_guardians.lrmm.strategies.base import DecisionContext, Strategy, _needs_head, _number

__all__ = ["SLIDE_MOVES", "SLIDE_TURNS", "RatedDriver", "Slide"]


def _rater(strategy: Strategy, guardian, observation_space, actions):
    """The :class:`~rmm_guardians.lrmm.nominal.PredictRater` of this env, or a ``ValueError``."""
    rater = None
    if guardian.inputs is None:  # a model reading one field cannot be given a predicted whole observation
        rater = make_rater(
            actions.controls,
            getattr(observation_space, "layout", None),
            guardian.model.candidate_hold,
            observation_space.low,
            observation_space.high,
        )
    if rater is None:
        raise ValueError(
            f"guardian {guardian.name!r}: strategy {strategy.name} rates the driver's control, so it needs the "
            "model reading the whole observation and a field the controls move ('velocity', 'speed', or "
            f"'heading' with evenly spaced rays; rmm_guardians.lrmm.nominal); got controls {actions.controls}, "
            f"inputs={guardian.inputs!r}"
        )
    return rater


class RatedDriver(Strategy):
    """Take control on the driver's next control rated, not on the state risk: the model's risk
    of the observation predicted after holding it (:mod:`rmm_guardians.lrmm.nominal`).  In control
    when that rating is above the threshold and the best head candidate is rated more than
    ``margin`` lower, or (``still``) holding still more than ``still`` lower; with ``stay``, it
    stays while the rating is above the threshold.  A step without the driver's control falls
    back on the state risk.

    Why: the quadrotor's state risk stays high near walls the driver is flying away from; the
    driver's own control rated tells a safe pass from a collision course."""

    PARAMS = ("margin", "still", "stay")
    reads_driver = True

    def __init__(self, margin: float = 0.0, still: float | None = None, stay: bool = True) -> None:
        self.margin = _number("RatedDriver margin", margin, 0.0)
        self.still = None if still is None else _number("RatedDriver still", still, 0.0)
        if not isinstance(stay, (bool, np.bool_)):
            raise ValueError(f"RatedDriver stay must be True or False, got {stay!r}")
        self.stay = bool(stay)
        self.last = math.nan

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        _rater(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        self._rater = _rater(self, guardian, guardian.observation_space, guardian.action_space)
        self._model = guardian.model
        self._cands = guardian.candidates
        self._zero = [0.0] * guardian.action_space.control_dim
        self.last = math.nan

    def take(self, step: DecisionContext, take: bool) -> bool:
        nominal = step.nominal
        if nominal is None:
            return take
        rated = self._rater.rate_many([nominal, self._zero, *self._cands], self._model, step.x)
        self.last = rated[0]
        return driver_at_risk(rated, step.threshold, self.margin, self.still, step.active and self.stay)

    def signals(self) -> dict[str, float]:
        return {"risk_driver": float(self.last)}


#: Slide's variants of the driver's velocity command: (cos, sin) of the turn of its horizontal
#: velocity, the fraction of that velocity kept, and the vertical velocity (``"climb"``: the
#: box's largest, or the fraction of the driver's kept)
SLIDE_MOVES = (((1.0, 0.0), 1.0, "climb"), ((1.0, 0.0), 0.5, "climb"), ((1.0, 0.0), 0.0, "climb"))
#: the moves ``Slide(turn=True)`` adds: the horizontal velocity turned a quarter to the left and to
#: the right at its full speed, and reversed at half of it, each climbing
SLIDE_TURNS = (((0.0, 1.0), 1.0, "climb"), ((0.0, -1.0), 1.0, "climb"), ((-1.0, 0.0), 0.5, "climb"))


class Slide(Strategy):
    """In control, apply the variant of the driver's velocity command nearest to it that the model
    rates at or below the threshold (climbing at its horizontal velocity, half of it or none,
    :data:`SLIDE_MOVES`; with ``turn``, also turned aside or backing off, :data:`SLIDE_TURNS`;
    other controls kept), else keep the control before it, or, with ``escape``, apply the variant
    rated lowest when it is rated lower than that control.

    Why: the quadrotor's driver mostly flies toward its goal; bending its command keeps that
    progress where replacing it with a fixed manoeuvre would throw it away.  Where every move is
    rated above the threshold (a pocket among objects), hovering kept the
    quadrotor in control at rest to the timeout: ``escape`` moves it down the rated risk until
    the driver's own command is rated safe again."""

    PARAMS = ("turn", "escape")
    SPEC_DEFAULTS = {"turn": False, "escape": False}
    reads_driver = True

    def __init__(self, turn: bool = False, escape: bool = False) -> None:
        for name, value in (("turn", turn), ("escape", escape)):
            if not isinstance(value, (bool, np.bool_)):
                raise ValueError(f"Slide {name} must be True or False, got {value!r}")
        self.turn, self.escape = bool(turn), bool(escape)

    def check(self, guardian, observation_space, actions) -> None:
        if any(c not in actions.controls for c in VELOCITY_CONTROLS):
            raise ValueError(
                f"guardian {guardian.name!r}: strategy Slide bends a velocity command: it needs the controls "
                f"{tuple(VELOCITY_CONTROLS)}, got {actions.controls}"
            )
        _rater(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        actions = guardian.action_space
        self._rater = _rater(self, guardian, guardian.observation_space, actions)
        self._model = guardian.model
        self.f, self.l, self.up = (actions.controls.index(c) for c in VELOCITY_CONTROLS)
        self._low, self._high = [float(v) for v in actions.control_low], [float(v) for v in actions.control_high]

    def variants(self, u) -> list[list[float]]:
        """The variants of ``u``, nearest first (Euclidean over the velocities; ties in the
        order of :data:`SLIDE_MOVES`, then :data:`SLIDE_TURNS`), ``u`` itself and repeats left out."""
        u = [float(v) for v in u]
        out = []
        for (c, s), k, z in SLIDE_MOVES + (SLIDE_TURNS if self.turn else ()):
            v = list(u)
            v[self.f] = k * (c * u[self.f] - s * u[self.l])
            v[self.l] = k * (s * u[self.f] + c * u[self.l])
            v[self.up] = self._high[self.up] if z == "climb" else z * u[self.up]
            v = [min(max(a, lo), hi) for a, lo, hi in zip(v, self._low, self._high, strict=True)]
            if v != u and v not in out:
                out.append(v)
        gap = [math.sqrt(sum((v[j] - u[j]) ** 2 for j in (self.f, self.l, self.up))) for v in out]
        return [out[i] for i in sorted(range(len(out)), key=lambda i: gap[i])]

    def act(self, step: DecisionContext, control):
        if not step.nominal:
            return control
        options = self.variants(step.nominal)
        if not options:
            return control
        if not self.escape:
            rated = self._rater.rate_many(options, self._model, step.x)
            return next((v for v, r in zip(options, rated, strict=True) if r <= step.threshold), control)
        before = [0.0] * len(options[0]) if control is None else [float(v) for v in control]
        *rated, rated_before = self._rater.rate_many(options + [before], self._model, step.x)
        safe = next((v for v, r in zip(options, rated, strict=True) if r <= step.threshold), None)
        if safe is not None:
            return safe
        best = min(range(len(options)), key=lambda i: rated[i])  # the first of equals: the nearest
        return options[best] if rated[best] < rated_before else control
