"""Baseline guardians: inactive, random, brakes-only (docs/original-code.md, items 17 and 23).

They need nothing but the parallel-autonomy contract: each builds its actions through the
action space given at ``reset`` and reads the control bounds from it, so they run on any
system whose env offers a :class:`rmm_envs.autonomy.GuardianActionSpace`.
"""

from __future__ import annotations

from guardians.base import Guardian

__all__ = ["BrakesGuardian", "InactiveGuardian", "RandomGuardian"]


class _ContractOnly(Guardian):
    """A guardian that needs only the action space (checked at reset)."""

    observation_type = "none"

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.require_action_space()


class InactiveGuardian(_ContractOnly):
    """Never takes control: the reckless driver alone."""

    name = "inactive"

    def act(self, observation, info):
        return self.action_space.inactive()


class RandomGuardian(_ContractOnly):
    """Takes control with probability ``p_active`` (0.5) and applies a control drawn uniformly
    over the action space's control box (drawn every step, also when it does not take control).

    Seeded through :meth:`reset` (the original sampled the action space unseeded).
    """

    name = "random"

    def __init__(self, p_active: float = 0.5) -> None:
        super().__init__()
        if not 0.0 <= p_active <= 1.0:
            raise ValueError(f"p_active must be a probability in [0, 1], got {p_active}")
        self.p_active = p_active

    def act(self, observation, info):
        space = self.action_space
        active = self.rng.random() < self.p_active
        u = self.rng.uniform(space.control_low, space.control_high)
        return space.active(u) if active else space.inactive()


class BrakesGuardian(Guardian):
    """Always in control, maximum braking.

    The first control (Dubins4D: the turn rate) is held constant for the episode and every
    other control (Dubins4D: the acceleration) at its lower bound, read from the action
    space: for Dubins4D that is full braking, ``u2 = -0.5``.  ``turn="random"`` (default, as
    the paper's code): the constant turn rate is drawn uniformly over its bounds
    (``[-0.25, 0.25]``) once per episode; ``turn="zero"``: no turn (the paper's text; zero
    clipped into the bounds).

    "Lowest value of every other control" is the safe default of Dubins4D only (for a
    quadrotor the lowest thrust is a fall): which control is safe is a property of the
    system, and other systems need their own definition before this baseline means
    "brake" for them.
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
        space = self.require_action_space()
        lo, hi = float(space.control_low[0]), float(space.control_high[0])
        self.turnrate = float(self.rng.uniform(lo, hi)) if self.turn == "random" else min(max(0.0, lo), hi)
        self._control = space.control_low.copy()
        self._control[0] = self.turnrate

    def act(self, observation, info):
        return self.action_space.active(self._control)
