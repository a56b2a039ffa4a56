"""The env ids this package registers, their naming scheme, and the renamed ids.

Every system has up to three envs, named after the system (``<System>``):

* ``<System>-v0``: plain control (the agent drives; no built-in driver);
* ``<System>Guarded-v0``: a built-in driver drives, a guardian may take over; blocking, fixed
  step (the guardian's compute time does not pass in the simulated world);
* ``<System>Parallel-v0``: the same, non-blocking (the guardian's compute time passes).

Ids used before this scheme stay registered as aliases (:data:`RENAMED`): making one warns
(``DeprecationWarning``, pointing at the caller) and builds the env of its new id.  Results a
benchmark stored under an old id keep their run keys: :func:`stored_id` is the id an env's
results are keyed under, the same for its old and its new id.
"""

from __future__ import annotations

import inspect
import sys
import warnings

import gymnasium as gym

__all__ = ["RENAMED", "canonical_id", "stored_id"]

#: Old id -> new id, for the ids renamed when one naming scheme was applied to every system.
RENAMED = {
    "Dubins4DCircles-v0": "Dubins4DCirclesGuarded-v0",
    "Dubins4DParallel-v0": "Dubins4DCirclesParallel-v0",
    "Dubins4DMap-v0": "Dubins4DMapGuarded-v0",
}
_STORED = {new: old for old, new in RENAMED.items()}


def canonical_id(env_id: str) -> str:
    """The current id of ``env_id`` (its new id if it was renamed, else itself)."""
    return RENAMED.get(env_id, env_id)


def stored_id(env_id: str) -> str:
    """The id the results of ``env_id`` are stored and keyed under: for a renamed env its old id
    (so results stored before the rename keep their keys), whichever of its two ids is given."""
    return _STORED.get(env_id, env_id)


def _caller_stacklevel() -> int:
    """The ``stacklevel`` of the first frame outside gymnasium and this module (the user's
    ``gym.make`` line), so that Python's default filter shows the warning to a script."""
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_globals.get("__name__", "").startswith(("gymnasium", __name__)):
        frame, level = frame.f_back, level + 1
    return level


class Renamed:
    """The entry point of an old id: warns, then builds the env (or vector env) of its new id."""

    def __init__(self, old: str, new: str, vector: bool = False) -> None:
        self.old, self.new, self.vector = old, new, vector

    def _target(self):
        spec = gym.spec(self.new)
        entry = spec.vector_entry_point if self.vector else spec.entry_point
        return gym.envs.registration.load_env_creator(entry) if isinstance(entry, str) else entry

    @property
    def __signature__(self) -> inspect.Signature:  # what the new id's entry point accepts
        return inspect.signature(self._target())

    def __call__(self, **kwargs):
        warnings.warn(f"env id {self.old!r} was renamed {self.new!r}; the old id still works but will be removed, "
                      f"use {self.new!r}", DeprecationWarning, stacklevel=_caller_stacklevel())
        return self._target()(**kwargs)

    def __repr__(self) -> str:
        return f"Renamed({self.old!r} -> {self.new!r})"


def register_aliases() -> None:
    """Register every old id of :data:`RENAMED` (after the new ids)."""
    for old, new in RENAMED.items():
        if old in gym.registry:
            continue
        vector = gym.spec(new).vector_entry_point
        gym.register(id=old, entry_point=Renamed(old, new), vector_entry_point=Renamed(old, new, True) if vector else None,
                     disable_env_checker=False)
