"""What the risk estimator needs of a system placed in a world: the :class:`RiskScene` protocol.

"System" in this project means *dynamics* (:mod:`rmm_envs.systems`); a *scene* is a dynamics
object placed in one obstacle configuration, and that is what the estimator labels.  The
estimator knows nothing else about it: a new scene is a class with these members (usually a
dynamics file in ``systems/`` plus a world in ``worlds/``, combined in :mod:`rmm_envs.scenes`).

Members (exactly what :class:`rmm_envs.risk.RiskEstimator` reads):
    state_dim: int, the length of a state vector.
    control_low, control_high: ``(control_dim,)`` arrays, the control box the estimator samples
        uniformly.
    propagate(states (N, d), controls (N, c), duration, n_steps) -> (N, n_steps, d): the path
        under a zero-order-hold control; point 0 is the start.
    path_failed(paths (N, S, d)) -> (N,) bool: any point or segment of the path fails.
    state_failed(states (N, d)) -> (N,) bool: the state itself fails.

Optional:
    leaf_estimate(states (N, d)) -> (N,) in [0, 1]: a value for non-failed leaves instead of 0.

Observing states for datasets is not the scene's concern but the env's
(:class:`rmm_envs.risk.labelled.LabelledEnv`).  ``System`` and ``check_system`` are the
deprecated former names of :class:`RiskScene` and :func:`check_scene`.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

__all__ = ["RiskScene", "System", "check_scene", "check_system"]

_REQUIRED = ("state_dim", "control_low", "control_high", "propagate", "path_failed", "state_failed")


@runtime_checkable
class RiskScene(Protocol):
    state_dim: int
    control_low: np.ndarray
    control_high: np.ndarray

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


#: Deprecated: the former name of :class:`RiskScene` (kept so existing imports work).
System = RiskScene
#: Deprecated: the former name of :func:`check_scene`.
check_system = check_scene
