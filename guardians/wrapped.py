"""Wrapped policies: any policy becomes a guardian.

* :class:`CallableGuardian` wraps ``fn(observation) -> action``.
* :class:`SB3Guardian` wraps an object with Stable-Baselines3's
  ``predict(observation, deterministic=True) -> (action, state)``.

Actions may be the env's dict, or a flat array ``[active, ...]`` (``active > 0.5`` means take
control), converted through the action space given at ``reset``: :class:`SB3Guardian` reads
``[active, z...]`` in the unit box exactly as :class:`rmm_envs.wrappers.FlattenGuardianAction`
does, through the same mapping (:meth:`rmm_envs.autonomy.GuardianActionSpace.from_unit`), so a
model trained through the wrapper applies the same controls here (``flat="raw"``: unscaled);
:class:`CallableGuardian` reads ``[active, u...]`` with ``u`` the control vector in the order of
the action space's ``controls`` (:func:`to_guardian_action`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace
from rmm_guardians.base import Guardian

__all__ = ["CallableGuardian", "FLAT_FORMS", "SB3Guardian", "to_guardian_action"]

#: How :class:`SB3Guardian` reads a flat action: in the unit box (``"unit"``, the training
#: wrapper's) or as the controls themselves (``"raw"``).
FLAT_FORMS = ("unit", "raw")


def to_guardian_action(action: Any, space: GuardianActionSpace | None) -> dict:
    """``action`` as the env's action dict: a dict passes through; a flat ``[active, u...]``
    becomes ``space.inactive()`` or ``space.active(u)``."""
    if isinstance(action, dict):
        return action
    if not isinstance(space, GuardianActionSpace):
        raise ValueError(
            f"a flat action {action!r} needs the env's action space (a GuardianActionSpace) to become "
            f"an action dict: pass reset(action_space=env.action_space), got {space!r}"
        )
    arr = np.asarray(action, dtype=float).reshape(-1)
    n = space.control_dim + 1
    if arr.shape != (n,):
        raise ValueError(
            f"a policy must return the env's action dict or [active, {', '.join(space.controls)}] "
            f"({n} numbers); got shape {np.shape(action)}"
        )
    return space.active(arr[1:]) if arr[0] > 0.5 else space.inactive()


class CallableGuardian(Guardian):
    """Wrap ``fn(observation) -> action`` (observation-only, so ``observation_type="local"``)."""

    def __init__(self, fn: Callable, name: str | None = None, observation_type: str = "local") -> None:
        super().__init__()
        if not callable(fn):
            raise TypeError(f"CallableGuardian needs a callable, got {fn!r}")
        self.fn = fn
        self.name = name if name else getattr(fn, "__name__", "callable")
        self.observation_type = observation_type

    def act(self, observation, info):
        return to_guardian_action(self.fn(observation), self.action_space)


class SB3Guardian(Guardian):
    """Wrap a model with ``predict(obs, deterministic=True)`` (Stable-Baselines3 style); a flat
    action is read as ``flat`` says (module docstring; default ``"unit"``, the training wrapper's)."""

    def __init__(self, model: Any, name: str = "sb3", deterministic: bool = True, flat: str = "unit") -> None:
        super().__init__()
        if not hasattr(model, "predict"):
            raise TypeError(
                f"SB3Guardian needs an object with predict(obs, deterministic=...), got {type(model).__name__}"
            )
        if flat not in FLAT_FORMS:
            raise ValueError(
                f"flat must be one of {FLAT_FORMS} (the unit box of FlattenGuardianAction, or the "
                f"controls unscaled), got {flat!r}"
            )
        self.model = model
        self.name = name
        self.deterministic = deterministic
        self.flat = flat

    def act(self, observation, info):
        out = self.model.predict(observation, deterministic=self.deterministic)
        action = out[0] if isinstance(out, tuple) else out
        if isinstance(action, dict) or self.flat == "raw":
            return to_guardian_action(action, self.action_space)
        self.require_action_space()
        return self.action_space.from_unit(action)
