"""The driver, the safe default, the failure test and the control names of
:func:`rmm_envs.envs.any_env.guarded`, as given by a user (a driver or safe default: a callable
``obs -> action``, an SB3-style policy or a constant action), checked against the env's action space
and turned into the guardian action's controls."""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from rmm_envs.adapters import termination_is_failure
from rmm_envs.adapters.base import control_box, env_actions
from rmm_envs.autonomy import SafeDefault

__all__ = [
    "Actions",
    "GivenSafeDefault",
    "as_policy",
    "callable_name",
    "control_names",
    "given_failure",
    "given_safe_default",
]


def callable_name(obj) -> str:
    return getattr(obj, "__qualname__", None) or type(obj).__name__


class Actions:
    """Conversions between the env's actions and the guardian's control vectors."""

    def __init__(self, space, env_name: str) -> None:
        self.space = space
        self.env_name = env_name
        self.discrete = isinstance(space, gym.spaces.Discrete)
        self.low, self.high = control_box(space, env_name)

    def check(self, action, who: str):
        """``action`` as the env takes it; ``ValueError`` naming ``who`` when it is outside the space."""
        arr = np.asarray(action)
        if self.discrete:
            ok = arr.size == 1 and arr.dtype.kind in "iu" and self.space.contains(int(arr.reshape(-1)[0]))
            if ok:
                return int(arr.reshape(-1)[0])
        else:
            ok = (
                arr.dtype.kind in "fiu"
                and arr.size == self.space.shape[0]
                and bool(np.all(np.isfinite(arr)))
                and bool(np.all((arr.reshape(-1) >= self.space.low) & (arr.reshape(-1) <= self.space.high)))
            )
            if ok:
                return arr.reshape(self.space.shape).astype(self.space.dtype)
        raise ValueError(f"{who} returned the action {action!r}, outside the env's action space {self.space}")

    def control(self, action) -> np.ndarray:
        """The control vector of a checked env action."""
        return np.asarray(action, dtype=float).reshape(-1)

    def action(self, control):
        """The env action of a control vector of the box."""
        a = env_actions(self.space, np.asarray(control, dtype=float).reshape(1, -1), self.low, self.high)[0]
        return int(a[0]) if self.discrete else a.astype(self.space.dtype)


def as_policy(obj, what: str):
    """``obj`` as a function ``obs -> action``: a callable, or an SB3-style ``predict``."""
    predict = getattr(obj, "predict", None)
    if callable(predict) and not callable(obj):
        return lambda obs: predict(obs, deterministic=True)[0]
    if callable(obj):
        return obj
    raise TypeError(
        f"{what} must be a callable obs -> action or an object with predict(obs, deterministic=True) "
        f"(an SB3-style policy), got {obj!r}"
    )


class GivenSafeDefault(SafeDefault):
    """The safe default handed to :func:`guarded`: a policy ``obs -> action`` or one constant action."""

    def __init__(self, fn, actions: Actions, constant=None) -> None:
        self._fn, self._actions, self._constant = fn, actions, constant
        self.description = f"the constant action {constant!r}" if fn is None else f"the policy {callable_name(fn)}"

    def policy(self, space, rng, **options):
        self.check_options(options)
        if self._fn is None:
            u = self._actions.control(self._constant)
            return lambda obs: u.copy()
        fn, acts = self._fn, self._actions
        return lambda obs: acts.control(acts.check(fn(obs), f"the safe default {callable_name(fn)}"))


def given_safe_default(safe_default, acts: Actions) -> GivenSafeDefault:
    """The safe default as given (a callable ``obs -> action``, an SB3-style policy or a constant
    action of the env's action space; ``TypeError`` for anything else)."""
    if callable(safe_default) or callable(getattr(safe_default, "predict", None)):
        return GivenSafeDefault(as_policy(safe_default, "safe_default"), acts)
    try:
        constant = acts.check(safe_default, "safe_default")
    except ValueError:
        raise TypeError(
            f"safe_default must be a callable obs -> action, an SB3-style policy or a constant "
            f"action in the env's action space {acts.space}, got {safe_default!r}"
        ) from None
    return GivenSafeDefault(None, acts, constant)


def control_names(controls, acts: Actions) -> tuple[str, ...]:
    """The guardian action's control names: ``controls`` (one per control of the env's action
    space; ``ValueError`` otherwise), ``u0, u1, ...`` when ``None``."""
    k = len(acts.low)
    names = (
        tuple(f"u{i}" for i in range(k)) if controls is None else () if isinstance(controls, str) else tuple(controls)
    )
    if len(names) != k:  # a string would be one name per letter
        hint = f" (a string; one name is {(controls,)!r})" if isinstance(controls, str) else ""
        raise ValueError(
            f"controls must name each control of {acts.env_name}'s action space {acts.space} "
            f"({k} control{'s' if k > 1 else ''}), got {controls!r}{hint}"
        )
    return names


def given_failure(failure, env: gym.Env, env_name: str, simulator: bool):
    """The failure test ``failure(obs) -> bool`` as given, or ``None`` where the env's termination
    (``failure="terminated"``, or an env whose termination the adapters know to be failure) or the
    simulator itself (``simulator``: one of your own, which takes none) reports failures."""
    if simulator and failure is not None:
        raise ValueError(
            f"failure: the simulator {env_name} reports its failures itself (its step returns True), "
            f"so guarded() takes no failure for it; got {failure!r}"
        )
    if failure is None and not simulator and not termination_is_failure(env):
        raise ValueError(
            f"{env_name} has no known failure notion (its termination means failure only for "
            "CartPole and the MuJoCo envs with an unhealthy state); give failure='terminated' if its "
            "termination is a failure, or failure=callable(obs) -> bool"
        )
    if not (failure is None or failure == "terminated" or callable(failure)):
        raise TypeError(f"failure must be None, 'terminated' or a callable failure(obs) -> bool, got {failure!r}")
    return None if failure in (None, "terminated") else failure
