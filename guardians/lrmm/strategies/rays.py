"""Strategies that turn by the rays: :class:`BrakeTurn` (the paper's avoidance) and
:class:`RayTurn` (the turn the model rates safer)."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.machine_independent import wrap_angle
from rmm_guardians.lrmm.strategies.base import DecisionContext, Strategy, _needs_rays, _number

__all__ = ["BrakeTurn", "RayTurn"]

_SIDE_RAY = math.pi / 6  # BrakeTurn compares the rays 30 degrees left and right of the heading


class BrakeTurn(Strategy):
    """The paper's avoidance: the strongest braking and the largest turn toward the more open of
    the rays 30 degrees left and right (none on a tie).  ``turn``, ``brake``: the turn rate and
    acceleration (``None``: the action space's largest turn rate and strongest braking).

    Why: the paper's rule, kept to reproduce it (``lrmm-paper``) and as the Dubins car's
    avoidance for a model without a head."""

    chooses = True

    PARAMS = ("turn", "brake")

    def __init__(self, turn: float | None = None, brake: float | None = None) -> None:
        self.turn = None if turn is None else _number("BrakeTurn turn", turn)
        self.brake = None if brake is None else _number("BrakeTurn brake", brake)

    def check(self, guardian, observation_space, actions) -> None:
        if actions.control_dim != 2 and actions.safe_default is not None:
            raise ValueError(
                f"guardian {guardian.name!r}: strategy BrakeTurn needs the Dubins car's two controls, got "
                f"{actions.control_dim} ({actions.controls}); this env states a safe default "
                f"({actions.safe_default.description}), which the core alone applies"
            )
        guardian.require_action_space(controls=2, space=actions)  # (turn rate, acceleration)
        _needs_rays(self, guardian, observation_space, actions)

    def reset(self, guardian) -> None:
        lay, actions = guardian.observation_space.layout, guardian.action_space
        self._left, self._right = lay.ray_index(_SIDE_RAY), lay.ray_index(-_SIDE_RAY)
        self._u1 = float(actions.control_high[0]) if self.turn is None else self.turn
        self._u2 = float(actions.control_low[1]) if self.brake is None else self.brake

    def act(self, step: DecisionContext, control):
        left, right = step.observation[self._left], step.observation[self._right]
        turn = 0.0 if np.isclose(left, right) else (self._u1 if left > right else -self._u1)
        return (turn, self._u2)


class RayTurn(Strategy):
    """Turn at the largest rate (or ``rate``) toward the side the model rates lower: its risk of
    the rays as they would read with the heading one ray further left or right; on a tie
    (``numpy.isclose``), toward the side whose nearest wall is farther, left on a second tie.

    Why: the maze car cannot stop, so its safe default is a turn; the model's own view of
    which side is safer avoids turning into a wall the nearest-wall rule cannot see."""

    chooses = True

    PARAMS = ("rate",)

    def __init__(self, rate: float | None = None) -> None:
        self.rate = None if rate is None else _number("RayTurn rate", rate, 0.0, lo_open=True)

    def check(self, guardian, observation_space, actions) -> None:
        guardian.require_action_space(controls=1, space=actions)  # the turn rate
        lay = _needs_rays(self, guardian, observation_space, actions)
        n = lay.size_of("rays")
        even = np.allclose(wrap_angle(np.asarray(lay.ray_angles) - 2 * np.pi * np.arange(n) / n), 0, atol=1e-9)
        if guardian.inputs != "rays" or not even:
            raise ValueError(
                f"guardian {guardian.name!r}: strategy RayTurn judges a turn by the model's risk of the rays "
                "rotated by one ray, so the model must read the 'rays' field, rays evenly spaced over the "
                f"full circle from the heading; got inputs={guardian.inputs!r}, ray angles {lay.ray_angles}"
            )

    def reset(self, guardian) -> None:
        lay = guardian.observation_space.layout
        rays = lay["rays"]
        angles = [math.remainder(a, 2 * math.pi) for a in lay.ray_angles]
        self._lside = [rays.start + i for i, a in enumerate(angles) if 0 < a < math.pi]
        self._rside = [rays.start + i for i, a in enumerate(angles) if -math.pi < a < 0]
        self._u1 = float(guardian.action_space.control_high[0]) if self.rate is None else self.rate
        self._model = guardian.model

    def act(self, step: DecisionContext, control):
        rays, observation = step.x, step.observation
        r_left, r_right = self._model.predict_all(np.stack([np.roll(rays, -1), np.roll(rays, 1)]))[:, 0]
        if not (math.isfinite(r_left) and math.isfinite(r_right)):
            raise ValueError(f"the LRMM model returned non-finite risks {[r_left, r_right]} for the turned rays")
        if np.isclose(r_left, r_right):
            left = min(observation[i] for i in self._lside) >= min(observation[i] for i in self._rside)
        else:
            left = r_left < r_right
        return (self._u1 if left else -self._u1,)
