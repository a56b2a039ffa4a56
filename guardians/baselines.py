"""Baseline guardians: inactive, random, brakes-only (docs/original-code.md, items 17 and 23)."""

from __future__ import annotations

import numpy as np

from guardians.base import Guardian, active_action, inactive_action

__all__ = ["BrakesGuardian", "InactiveGuardian", "RandomGuardian"]

U1 = (-0.25, 0.25)
U2 = (-0.5, 0.5)


class InactiveGuardian(Guardian):
    """Never takes control: the reckless driver alone."""

    name = "inactive"
    observation_type = "none"

    def act(self, observation, info):
        return inactive_action()


class RandomGuardian(Guardian):
    """Takes control with probability ``p_active`` (0.5) and applies a uniform control.

    Seeded through :meth:`reset` (the original sampled the action space unseeded).
    """

    name = "random"
    observation_type = "none"

    def __init__(self, p_active: float = 0.5) -> None:
        super().__init__()
        if not 0.0 <= p_active <= 1.0:
            raise ValueError(f"p_active must be a probability in [0, 1], got {p_active}")
        self.p_active = p_active

    def act(self, observation, info):
        active = self.rng.random() < self.p_active
        u1 = self.rng.uniform(*U1)
        u2 = self.rng.uniform(*U2)
        return active_action(u1, u2) if active else inactive_action()


class BrakesGuardian(Guardian):
    """Always in control, maximum braking.

    ``turn="random"`` (default, as the paper's code): a constant turn rate drawn uniformly on
    ``[-0.25, 0.25]`` once per episode; ``turn="zero"``: no turn (the paper's text).
    """

    name = "brakes"
    observation_type = "none"

    def __init__(self, turn: str = "random") -> None:
        super().__init__()
        if turn not in ("random", "zero"):
            raise ValueError(f"turn must be 'random' or 'zero', got {turn!r}")
        self.turn = turn
        self.turnrate = 0.0

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.turnrate = float(self.rng.uniform(*U1)) if self.turn == "random" else 0.0

    def act(self, observation, info):
        return active_action(self.turnrate, U2[0])
