"""An episode's start: its fingerprint, and whether it was already doomed.

Offers :func:`start_fingerprint`, :func:`world_key`, :class:`StartAssessment`,
:func:`assess_start` and :func:`has_doomed_test` (the test an env carries, or its system's).

Every agent of an ``rmm-bench`` run meets the same episodes: episode ``i`` resets the env with
the same seed, so it starts from the same state in the same world whatever the agent or the
clock.  The fingerprint is how a result says which start it had, so that results of two runs
(other directories, other code versions) are paired only where their starts are the same.  The
doomed test says whether a start could be saved at all; it depends on the start state and the
env's base step alone, never on an agent or the clock.
"""

from __future__ import annotations

import hashlib
import json
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from rmm_envs.catalog import GUARDED_VARIANTS, load_ref, system_of_env

__all__ = [
    "StartAssessment",
    "assess_start",
    "has_doomed_test",
    "start_fingerprint",
    "world_key",
]

#: env keyword arguments that change how an episode is timed, never where it starts
TIMING_KWARGS = frozenset({"clock", "time_accel"})
#: env options that never shape a start: timing, and disturbances (drawn from streams of their
#: own, so a disturbed episode starts where the undisturbed one does; its doomed flag is the
#: nominal model's)
UNSHAPING_KWARGS = TIMING_KWARGS | {"disturbances"}


def _feed(h, value: Any, depth: int = 0) -> None:
    """Feed ``value`` to the hash ``h`` canonically: numbers as float64 bytes, arrays with their
    shape, mappings by sorted key, sequences in order, other objects by their public
    attributes (a maze's walls, a room's boxes), at most four levels deep."""
    if value is None or isinstance(value, bool | int | float | np.number | np.bool_):
        h.update(b"n" + struct.pack("<d", float(value) if value is not None else float("nan")))
    elif isinstance(value, str):
        h.update(b"s" + value.encode() + b"\0")
    elif isinstance(value, np.ndarray) or (isinstance(value, list | tuple) and _numeric(value)):
        a = np.ascontiguousarray(np.asarray(value, dtype="<f8"))
        h.update(b"a" + struct.pack(f"<{a.ndim + 1}q", a.ndim, *a.shape) + a.tobytes())
    elif isinstance(value, dict):
        h.update(b"d")
        for k in sorted(value, key=str):
            h.update(str(k).encode() + b"=")
            _feed(h, value[k], depth + 1)
    elif isinstance(value, list | tuple):
        h.update(b"l" + struct.pack("<q", len(value)))
        for v in value:
            _feed(h, v, depth + 1)
    elif depth < 4 and hasattr(value, "__dict__"):
        attrs = {k: v for k, v in vars(value).items() if not k.startswith("_") and not callable(v)}
        h.update(b"o" + type(value).__name__.encode())
        _feed(h, attrs, depth + 1)
    else:
        h.update(b"t" + type(value).__name__.encode())


def _numeric(seq) -> bool:
    try:
        a = np.asarray(seq)
    except (ValueError, TypeError):
        return False
    return a.dtype.kind in "biuf" and a.size > 0


def start_fingerprint(env, observation) -> str:
    """16 hex digits identifying an episode's start: the SHA-256 of the first observation and,
    where the env offers :meth:`privileged` (every built-in system), its true state and world
    (obstacles, walls, goal, waypoints), taken right after ``reset``."""
    h = hashlib.sha256()
    _feed(h, observation if not isinstance(observation, dict) else dict(observation))
    privileged = getattr(env.unwrapped, "privileged", None)
    if callable(privileged):
        try:
            world = privileged()
        except Exception:  # an env whose privileged view needs more than a reset: the observation alone
            world = None
        if isinstance(world, dict):
            _feed(h, {k: v for k, v in world.items() if k != "sim_time"})
    return h.hexdigest()[:16]


def world_key(env_id: str, env_kwargs: dict, seed: int) -> str:
    """The identity of a run's episode starts: its env, the env's options that shape a start
    (all but :data:`UNSHAPING_KWARGS`) and the run's seed; 16 hex digits.  Runs with the same key
    share their starts (and their doomed flags), whatever their agents, clocks and disturbances."""
    shaped = {k: v for k, v in sorted(env_kwargs.items()) if k not in UNSHAPING_KWARGS}
    text = json.dumps({"env_id": env_id, "env_kwargs": shaped, "seed": int(seed)}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class StartAssessment:
    """Whether a start was doomed: ``doomed`` True (no control the env allows avoids a
    collision), False (one does: the start is avoidable), None (not assessed: the env has no
    test); ``method`` names the test (``""`` when none)."""

    doomed: bool | None
    method: str = ""


def _test_of(env) -> Callable[[Any], StartAssessment] | None:
    """The doomed test of ``env``: the one the env carries (``env.unwrapped.doomed_test``, as a
    simulator's ``start_doomed`` hook gives it), else its system's
    (:attr:`rmm_envs.catalog.SystemSpec.doomed_test`, for the system's guarded envs)."""
    own = getattr(env.unwrapped, "doomed_test", None)
    if callable(own):
        return own
    found = system_of_env(env)
    if found is None or found[1] not in GUARDED_VARIANTS or found[0].doomed_test is None:
        return None
    return load_ref(found[0].doomed_test)


def has_doomed_test(env) -> bool:
    """Whether :func:`assess_start` has a test for ``env``."""
    return _test_of(env) is not None


def assess_start(env) -> StartAssessment:
    """The doomed test of ``env`` (after ``reset``, :func:`_test_of`); ``StartAssessment(None)`` when none applies."""
    test = _test_of(env)
    return StartAssessment(None) if test is None else test(env)
