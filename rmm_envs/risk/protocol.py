"""The small protocol a system must offer to be risk-labelled.

The estimator knows nothing else about a system: a new system is a class with these members
(usually a dynamics file in ``systems/`` plus a world in ``worlds/``, combined by its env).

Members:
    state_dim, control_dim: ints.
    control_low, control_high: ``(control_dim,)`` arrays, the control box.
    sample_controls(rng, n) -> (n, control_dim): the default (uniform) sampling policy.
    propagate(states (N, d), controls (N, c), duration, n_steps) -> (N, n_steps, d): the path
        under a zero-order-hold control; point 0 is the start.
    path_failed(paths (N, S, d)) -> (N,) bool: any point or segment of the path fails.
    state_failed(states (N, d)) -> (N,) bool: the state itself fails.
    observe(states (N, d), ...) -> (N, obs_dim): the local observation (for datasets).

Optional:
    leaf_estimate(states (N, d)) -> (N,) in [0, 1]: a value for non-failed leaves instead of 0.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["SceneBase", "System", "check_system"]

_REQUIRED = ("state_dim", "control_dim", "control_low", "control_high", "sample_controls",
             "propagate", "path_failed", "state_failed", "observe")


@runtime_checkable
class System(Protocol):
    state_dim: int
    control_dim: int
    control_low: np.ndarray
    control_high: np.ndarray

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray: ...

    def propagate(self, states: np.ndarray, controls: np.ndarray, duration: float, n_steps: int) -> np.ndarray: ...

    def path_failed(self, paths: np.ndarray) -> np.ndarray: ...

    def state_failed(self, states: np.ndarray) -> np.ndarray: ...

    def observe(self, states: np.ndarray, *args, **kwargs) -> np.ndarray: ...


def check_system(system) -> None:
    """Raise ``TypeError`` naming what ``system`` lacks of the :class:`System` protocol."""
    missing = [m for m in _REQUIRED if not hasattr(system, m)]
    if missing:
        raise TypeError(
            f"{type(system).__name__} is not a risk System: it lacks {missing} "
            f"(see rmm_envs.risk.protocol for what the estimator needs)"
        )


class SceneBase:
    """A dynamics object placed in a world: the dynamics part of :class:`System`, delegated.

    Subclasses set ``self.system`` (with ``control_low``/``control_high``, ``sample_controls``
    and ``propagate``) and implement ``state_failed``, ``path_failed`` and ``observe``.
    """

    system = None

    @property
    def control_low(self) -> np.ndarray:
        return self.system.control_low

    @property
    def control_high(self) -> np.ndarray:
        return self.system.control_high

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return self.system.sample_controls(rng, n)

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        return self.system.propagate(states, controls, duration, n_steps)
