"""Adapters: any policy becomes a guardian.

* :class:`CallableGuardian` wraps ``fn(observation) -> action``.
* :class:`SB3Guardian` wraps an object with Stable-Baselines3's
  ``predict(observation, deterministic=True) -> (action, state)``.

Actions may be the env's dict, or a flat array ``[active, turnrate, accel]`` (active > 0.5
means take control), which is converted to the dict.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from guardians.base import Guardian

__all__ = ["CallableGuardian", "SB3Guardian", "to_guardian_action"]


def to_guardian_action(action: Any) -> dict:
    if isinstance(action, dict):
        return action
    arr = np.asarray(action, dtype=float).reshape(-1)
    if arr.shape != (3,):
        raise ValueError(
            f"a policy must return the env's action dict or [active, turnrate, accel]; got shape {np.shape(action)}"
        )
    return {"active_ctrl": int(arr[0] > 0.5), "turnrate_ctrl": np.array([arr[1]], np.float32),
            "accel_ctrl": np.array([arr[2]], np.float32)}


class CallableGuardian(Guardian):
    """Wrap ``fn(observation) -> action`` (observation-only, so ``observation_type="local"``)."""

    def __init__(self, fn: Callable, name: str | None = None, observation_type: str = "local") -> None:
        super().__init__()
        if not callable(fn):
            raise TypeError(f"CallableGuardian needs a callable, got {fn!r}")
        self.fn = fn
        self.name = name or getattr(fn, "__name__", "callable")
        self.observation_type = observation_type

    def act(self, observation, info):
        return to_guardian_action(self.fn(observation))


class SB3Guardian(Guardian):
    """Wrap a model with ``predict(obs, deterministic=True)`` (Stable-Baselines3 style)."""

    def __init__(self, model: Any, name: str = "sb3", deterministic: bool = True) -> None:
        super().__init__()
        if not hasattr(model, "predict"):
            raise TypeError(f"SB3Guardian needs an object with predict(obs, deterministic=...), got {type(model).__name__}")
        self.model = model
        self.name = name
        self.deterministic = deterministic

    def act(self, observation, info):
        out = self.model.predict(observation, deterministic=self.deterministic)
        action = out[0] if isinstance(out, tuple) else out
        return to_guardian_action(action)
