"""The part every scene shares: its dynamics object's control box and propagation, delegated."""

from __future__ import annotations

from typing import Protocol

import numpy as np

__all__ = ["Dynamics", "SceneBase", "branch_inputs"]


class Dynamics(Protocol):
    """What a scene reads of its dynamics object (every class of a system's ``dynamics.py`` has it)."""

    @property
    def control_low(self) -> np.ndarray: ...

    @property
    def control_high(self) -> np.ndarray: ...

    def sample_controls(self, rng: np.random.Generator, n: int, /) -> np.ndarray: ...

    def propagate(self, states: np.ndarray, controls: np.ndarray, duration: float, n_steps: int, /) -> np.ndarray: ...


class SceneBase:
    """A dynamics object placed in a world: the dynamics part of :class:`rmm_envs.risk.RiskScene`.

    Subclasses set ``self.dynamics`` (a dynamics object of a system's ``dynamics.py``, with
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

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``(failed (N,) bool, ends (N, d))``: ``path_failed`` of the paths ``propagate`` gives and
        each path's last state, what the risk estimator reads of a tree level.  This composes
        the two; a scene with a fused compiled loop overrides it with the same bits."""
        paths = self.propagate(states, controls, duration, n_steps)
        return np.asarray(self.path_failed(paths), dtype=bool), paths[:, -1]  # type: ignore[attr-defined]


def branch_inputs(states, controls, duration: float, n_steps: int, state_dim: int, control_dim: int):
    """``(states, controls, times)`` for a fused ``propagate_failed``: contiguous float arrays
    ``(N, state_dim)`` and ``(N, control_dim)`` and the path times ``np.linspace(0, duration,
    n_steps)`` (the dynamics' own), or ``ValueError`` naming the bad argument as ``propagate`` does."""
    states = np.ascontiguousarray(states, dtype=float)
    controls = np.ascontiguousarray(controls, dtype=float).reshape(states.shape[0] if states.ndim == 2 else -1, -1)
    if states.ndim != 2 or states.shape[1] != state_dim:
        raise ValueError(f"states must have shape (N, {state_dim}), got {states.shape}")
    if controls.shape != (states.shape[0], control_dim):
        raise ValueError(
            f"controls must have shape ({states.shape[0]}, {control_dim}) to match states, got {controls.shape}"
        )
    if not np.isfinite(duration) or duration < 0:
        raise ValueError(f"duration must be a finite number >= 0, got {duration}")
    if int(n_steps) != n_steps or n_steps < 2:
        raise ValueError(f"n_steps must be an integer >= 2, got {n_steps}")
    return states, controls, np.linspace(0.0, float(duration), int(n_steps))
