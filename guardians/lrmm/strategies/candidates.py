"""Strategies that apply a control the action-conditioned head rates: :class:`SafestCandidate`
and :class:`Restart`."""

from __future__ import annotations

import numpy as np

from rmm_guardians.lrmm.strategies.base import DecisionContext, Strategy, _candidate_risks, _needs_head, _number

__all__ = ["Restart", "SafestCandidate"]


class SafestCandidate(Strategy):
    """Apply the head candidate the model rates safest (the first of the lowest).

    The action-conditioned head rates each of a few candidate controls by the risk after
    holding it; in control, the guardian applies the one rated lowest instead of the env's fixed
    safe default.  Why: on Dubins4D full braking straight on often ends in the obstacle ahead,
    while a rated turn clears it."""

    chooses = True

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        cands = guardian.model.candidates
        if cands.shape[1] != actions.control_dim:
            k = cands.shape[1]
            raise ValueError(
                f"guardian {guardian.name!r} needs an action space with {k} controls (the model's candidate "
                f"controls have {k} components), got {actions.control_dim} ({actions.controls})"
            )
        low, high = np.asarray(actions.control_low, float), np.asarray(actions.control_high, float)
        outside = [c.tolist() for c in cands if np.any(c < low) or np.any(c > high)]
        if outside:
            raise ValueError(
                f"guardian {guardian.name!r}: candidate controls {outside} of "
                f"{getattr(guardian.model, 'path', 'the model')} lie outside the env's control bounds "
                f"[{low.tolist()}, {high.tolist()}] ({actions.controls})"
            )

    def reset(self, guardian) -> None:
        self._cands = guardian.candidates

    def act(self, step: DecisionContext, control):
        cand = _candidate_risks(step)
        return self._cands[cand.index(min(cand))]


class Restart(Strategy):
    """A car in control below ``speed`` (m/s) applies the safest head candidate that accelerates,
    when one is rated at or below the threshold; else the control before it is kept, or, with
    ``turn``, the car turns where it stands: the head candidate that turns without accelerating,
    rated lowest on the side it first chose, until an accelerating one is rated safe.

    Why: a car the guardian braked to a stop is never at risk again and never reaches its goal,
    so a guardian that only brakes turns collisions into timeouts; and a car stopped facing an
    obstacle stays stopped while every way forward is rated unsafe, where turning in place (a
    Dubins car turns at any speed) brings a way out into view."""

    PARAMS = ("speed", "turn")
    SPEC_DEFAULTS = {"turn": False}

    def __init__(self, speed: float = 0.3, turn: bool = False) -> None:
        self.speed = _number("Restart speed", speed, 0.0)
        if not isinstance(turn, (bool, np.bool_)):
            raise ValueError(f"Restart turn must be True or False, got {turn!r}")
        self.turn = bool(turn)
        self._side = 0.0

    def check_model(self, model, inputs) -> None:
        _needs_head(self, model)

    def check(self, guardian, observation_space, actions) -> None:
        if "accel_ctrl" not in actions.controls or "speed" not in getattr(observation_space, "layout", ()):
            raise ValueError(
                f"guardian {guardian.name!r}: strategy Restart needs an 'accel_ctrl' control and a 'speed' "
                f"observation field, got controls {actions.controls}"
            )
        if self.turn and "turnrate_ctrl" not in actions.controls:
            raise ValueError(
                f"guardian {guardian.name!r}: strategy Restart(turn=True) turns the car: it needs a "
                f"'turnrate_ctrl' control, got controls {actions.controls}"
            )

    def reset(self, guardian) -> None:
        self._cands = guardian.candidates
        self._speed = guardian.observation_space.layout.index("speed")
        self._accel = guardian.action_space.controls.index("accel_ctrl")
        controls = guardian.action_space.controls
        self._turn = controls.index("turnrate_ctrl") if "turnrate_ctrl" in controls else None
        self._side = 0.0

    def act(self, step: DecisionContext, control):
        if not step.observation[self._speed] < self.speed:
            self._side = 0.0
            return control
        cand = _candidate_risks(step)
        go = [(r, i) for i, r in enumerate(cand) if self._cands[i][self._accel] > 0 and r <= step.threshold]
        if go:
            self._side = 0.0
            return self._cands[min(go)[1]]
        if not self.turn or self._turn is None:
            return control
        turns = [
            (r, i)
            for i, r in enumerate(cand)
            if self._cands[i][self._accel] <= 0
            and self._cands[i][self._turn] != 0
            and (self._side == 0.0 or np.sign(self._cands[i][self._turn]) == self._side)
        ]
        if not turns:
            return control
        best = self._cands[min(turns)[1]]
        self._side = float(np.sign(best[self._turn]))
        return best
