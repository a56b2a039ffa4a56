"""Baseline guardians: inactive, random, brakes-only (docs/original-code.md, items 17 and 23).

They need nothing but the parallel-autonomy contract: each builds its actions through the
action space given at ``reset`` and reads the control bounds from it, so they run on any
system whose env offers a :class:`rmm_envs.autonomy.GuardianActionSpace`; ``brakes`` also
needs the space's ``safe_default`` (the system's own safe behaviour), and is refused before any
episode on an env that states none.
"""

from __future__ import annotations

from rmm_guardians.base import Guardian

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
    """Always in control, applying the system's safe default.

    The safe default is the env's: its action space's ``safe_default``
    (:class:`rmm_envs.autonomy.SafeDefault`), full braking for Dubins4D, the maximum turn away
    from the nearer wall for the maze car.  An env whose action space states none is refused at
    :meth:`reset`, naming what is missing.

    ``turn`` (Dubins4D's braking only): ``"random"`` (default, as the paper's code) holds a turn
    rate drawn uniformly over its bounds (``[-0.25, 0.25]``) once per episode; ``"zero"`` no
    turn (the paper's text).  ``None`` leaves the safe default's own choice (``"random"`` for
    Dubins4D); a safe default without a turn choice refuses a given ``turn``.
    """

    name = "brakes"
    observation_type = "none"

    def __init__(self, turn: str | None = None) -> None:
        super().__init__()
        if turn not in (None, "random", "zero"):
            raise ValueError(f"turn must be 'random' or 'zero', got {turn!r}")
        self.turn = turn
        self._policy = None

    def check_spaces(self, observation_space, action_space) -> None:
        space = self.require_action_space(space=action_space)
        if space.safe_default is None:
            raise ValueError(
                f"guardian {self.name!r} applies the env's safe default, and this env's action space "
                "states none (GuardianActionSpace(safe_default=...), rmm_envs.autonomy.SafeDefault)"
            )
        if self.turn is not None:
            try:
                space.safe_default.check_options({"turn": self.turn})
            except ValueError as e:
                raise ValueError(f"guardian {self.name!r}: {e}") from None

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        space = self.action_space
        # check_spaces refused a space that is not a GuardianActionSpace or states no safe default
        assert space is not None and space.safe_default is not None
        options = {} if self.turn is None else {"turn": self.turn}
        try:
            self._policy = space.safe_default.policy(space, self.rng, **options)
        except ValueError as e:
            raise ValueError(f"guardian {self.name!r}: {e}") from None

    def act(self, observation, info):
        return self.action_space.active(self._policy(observation))
