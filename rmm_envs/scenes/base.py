"""The part every scene shares: its dynamics object's control box and propagation, delegated."""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["Dynamics", "SceneBase"]


class Dynamics(Protocol):
    """What a scene reads of its dynamics object (every class of :mod:`rmm_envs.dynamics` has it)."""

    @property
    def control_low(self) -> np.ndarray: ...

    @property
    def control_high(self) -> np.ndarray: ...

    def sample_controls(self, rng: np.random.Generator, n: int, /) -> np.ndarray: ...

    def propagate(self, states: np.ndarray, controls: np.ndarray, duration: float, n_steps: int, /) -> np.ndarray: ...


class SceneBase:
    """A dynamics object placed in a world: the dynamics part of :class:`rmm_envs.risk.RiskScene`.

    Subclasses set ``self.dynamics`` (a dynamics object of :mod:`rmm_envs.dynamics`, with
    ``control_low``/``control_high``, ``sample_controls`` and ``propagate``) and ``state_dim``,
    and implement ``state_failed`` and ``path_failed``.
    """

    dynamics: Dynamics

    @property
    def control_low(self) -> np.ndarray:
        return self.dynamics.control_low

    @property
    def control_high(self) -> np.ndarray:
        return self.dynamics.control_high

    @property
    def control_dim(self) -> int:
        return len(self.dynamics.control_low)

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``(n, control_dim)`` controls uniform on the box (the dynamics object's sampler)."""
        return self.dynamics.sample_controls(rng, n)

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        return self.dynamics.propagate(states, controls, duration, n_steps)
