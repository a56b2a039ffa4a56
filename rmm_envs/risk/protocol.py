"""The two protocols of risk labelling: :class:`RiskScene` (what the estimator needs of a system
placed in a world) and :class:`LabelledEnv` (what ``RiskLabel`` and ``rmm-datagen`` need of an env).

A *scene* is a dynamics object (a system's dynamics, ``rmm_envs/systems/<system>/``) placed in one obstacle configuration,
and that is what the estimator labels: ``state_dim``, the control box ``control_low`` /
``control_high``, ``propagate``, ``path_failed``, ``state_failed`` and optionally
``leaf_estimate``.  A labelled env offers ``risk_scene()``, ``true_state``, ``sample_states``,
``observe_states``, ``privileged()`` and ``dataset_notes()`` on its unwrapped env.  Each
member's contract is in its class's docstring; :func:`check_scene` and
:func:`check_labelled_env` check an object against them, naming each missing or ill-formed
member.

Two protocols because observing states for datasets is the env's concern, not the scene's.
"""

from __future__ import annotations

import inspect
from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["HOOKS", "LabelledEnv", "RiskScene", "check_labelled_env", "check_scene"]

_REQUIRED = ("state_dim", "control_low", "control_high", "propagate", "path_failed", "state_failed")


@runtime_checkable
class RiskScene(Protocol):
    """A dynamics object placed in one obstacle configuration: what the estimator labels.

    Members (exactly what :class:`rmm_envs.risk.RiskEstimator` reads)::

        state_dim: int, the length of a state vector.
        control_low, control_high: ``(control_dim,)`` arrays, the control box the estimator samples
            uniformly.
        propagate(states (N, d), controls (N, c), duration, n_steps) -> (N, n_steps, d): the path
            under a zero-order-hold control; point 0 is the start.
        path_failed(paths (N, S, d)) -> (N,) bool: any point or segment of the path fails.
        state_failed(states (N, d)) -> (N,) bool: the state itself fails.

    Optional::

        leaf_estimate(states (N, d)) -> (N,) in [0, 1]: a value for non-failed leaves instead of 0.
        propagate_failed(states (N, d), controls (N, c), duration, n_steps) -> (failed (N,) bool,
            ends (N, d)): ``path_failed(propagate(...))`` and each path's last state in one call,
            the same bits (the ``ends`` row of a failed branch may be any state: nothing reads it).
            The estimator uses it where it is defined (``fused=True``); the package's scenes
            run it as one compiled loop per tree level (:mod:`rmm_envs.scenes.branch_kernels`).
    """

    state_dim: int

    @property
    def control_low(self) -> np.ndarray: ...

    @property
    def control_high(self) -> np.ndarray: ...

    def propagate(self, states: np.ndarray, controls: np.ndarray, duration: float, n_steps: int) -> np.ndarray: ...

    def path_failed(self, paths: np.ndarray) -> np.ndarray: ...

    def state_failed(self, states: np.ndarray) -> np.ndarray: ...


def check_scene(scene) -> None:
    """Raise ``TypeError`` naming what ``scene`` lacks of the :class:`RiskScene` protocol."""
    missing = [m for m in _REQUIRED if not hasattr(scene, m)]
    if missing:
        raise TypeError(
            f"{type(scene).__name__} is not a RiskScene: it lacks {missing} "
            f"(see rmm_envs.risk.protocol for what the estimator needs)"
        )


@runtime_checkable
class LabelledEnv(Protocol):
    """An environment whose states can be risk-labelled, on its unwrapped env (every env of this
    package is one, through :class:`rmm_envs.envs.base.LabelledEnvBase`).

    ``risk_scene() -> RiskScene``
        The :class:`rmm_envs.risk.RiskScene` of the current episode (its dynamics in its obstacle
        configuration); ``RuntimeError`` before the first ``reset``.
    ``true_state``
        Property: the current true state, a ``(state_dim,)`` float array (a copy).
    ``sample_states(rng, n) -> (n, state_dim)``
        ``n`` states of the current episode's scene for a dataset, drawn from the
        ``numpy.random.Generator`` ``rng`` only (so a seed fixes them).
    ``observe_states(states, rng=None) -> (n, obs_dim) float32``
        The observations the env would return in those states.  ``rng`` draws any feature that a
        state does not determine (the Dubins4D simulated time); envs without such a feature ignore
        it, envs with one require it.
    ``privileged() -> dict``
        The true state and the obstacle geometry (copies): **privileged** information, for
        guardians that declare they use it and for analysis.
    ``dataset_notes() -> dict``
        Facts about ``observe_states`` that a dataset records in its metadata
        (``{"obs_time_feature": description or None}``).

    :func:`check_labelled_env` checks an env against this list (on its class, so before any
    ``reset``) and names the env and each missing or ill-formed hook.
    """

    def risk_scene(self) -> RiskScene: ...

    @property
    def true_state(self) -> np.ndarray: ...

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray: ...

    def observe_states(self, states: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray: ...

    def privileged(self) -> dict: ...

    def dataset_notes(self) -> dict: ...


#: hook -> the positional arguments a call passes (``None``: a property, not called)
HOOKS: dict[str, tuple[str, ...] | None] = {
    "risk_scene": (),
    "true_state": None,
    "sample_states": ("rng", "n"),
    "observe_states": ("states", "rng"),
    "privileged": (),
    "dataset_notes": (),
}


def _env_name(env) -> str:
    spec_id = getattr(getattr(env, "spec", None), "id", None)
    name = type(env).__name__
    return f"{spec_id} ({name})" if spec_id else name


def check_labelled_env(env, needs: tuple[str, ...] = tuple(HOOKS)) -> None:
    """Raise ``TypeError`` naming ``env`` and each hook of ``needs`` (default: all of
    :data:`HOOKS`) that its unwrapped env lacks or cannot be called as the protocol calls it.
    Hooks are looked up on the class, so the check needs no ``reset``."""
    base = getattr(env, "unwrapped", env)
    cls = type(base)
    problems = []
    for hook in needs:
        args = HOOKS[hook]
        member = inspect.getattr_static(cls, hook, None)
        if member is None:
            problems.append(f"{hook} is missing")
        elif args is None:
            if callable(member) and not isinstance(member, property):
                problems.append(f"{hook} must be a property or attribute, not a method")
        elif not callable(member):
            problems.append(f"{hook} must be a method taking ({', '.join(args)})")
        else:
            try:
                inspect.signature(member).bind(None, *args)
            except TypeError:
                problems.append(f"{hook}{inspect.signature(member)} cannot be called as {hook}({', '.join(args)})")
            except ValueError:  # no signature (a builtin): assume it fits
                pass
    if problems:
        raise TypeError(f"{_env_name(base)} is not a LabelledEnv (see rmm_envs.risk.protocol): " + "; ".join(problems))
