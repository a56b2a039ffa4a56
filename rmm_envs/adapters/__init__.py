"""Risk maps for simulators the project did not write (see :mod:`rmm_envs.adapters.base` for the
snapshot protocol, and the tutorial ``docs/tutorials/own-simulator.md``).

:func:`adapt` turns a Gymnasium env into an :class:`AdaptedEnv` (the
:class:`rmm_envs.risk.LabelledEnv` hooks), choosing by the env's class:

* ``CartPole-v1``: :class:`CartPoleAdapter` (numpy), failure: its termination;
* ``Pendulum-v1``: :class:`PendulumAdapter` (numpy), failure: ``failure=`` (required);
* ``InvertedPendulum-v5``, ``InvertedDoublePendulum-v5``, ``Hopper-v5``: :class:`MujocoAdapter`
  (rollout), failure: the unhealthy termination; any other MuJoCo env: ``failure=`` (required),
  a test of full states, column 0 the time (:mod:`rmm_envs.adapters.mujoco_envs`; Walker2d's ships).

The MuJoCo adapters need the optional extra ``rmm-envs[mujoco]``.  Any other env is refused
with a ``TypeError`` naming it and what it lacks; a simulator of your own is served by
:class:`SnapshotScene` once it follows :class:`SnapshotSimulator`.
"""

from __future__ import annotations

import gymnasium as gym
from gymnasium.envs.classic_control import CartPoleEnv, PendulumEnv

from rmm_envs.adapters.base import AdaptedEnv, SimulatorScene, SnapshotScene, SnapshotSimulator, control_box
from rmm_envs.adapters.classic_control import (
    CartPoleAdapter,
    CartPoleScene,
    ClassicControlSnapshot,
    PendulumAdapter,
    PendulumScene,
)
from rmm_envs.risk.protocol import check_labelled_env

__all__ = [
    "AdaptedEnv",
    "CartPoleAdapter",
    "CartPoleScene",
    "ClassicControlSnapshot",
    "PendulumAdapter",
    "PendulumScene",
    "SimulatorScene",
    "SnapshotScene",
    "SnapshotSimulator",
    "adapt",
    "control_box",
    "snapshot_of",
    "termination_is_failure",
]

SERVED = (
    "CartPole-v1",
    "Pendulum-v1 (with failure=)",
    "InvertedPendulum-v5",
    "InvertedDoublePendulum-v5",
    "Hopper-v5",
    "any other MuJoCo env (with failure=)",
)


def _env_name(env) -> str:
    env_id = getattr(getattr(env, "spec", None), "id", None)
    return f"{env_id} ({type(env.unwrapped).__name__})" if env_id else type(env.unwrapped).__name__


def _is_mujoco(base) -> bool:
    return any(
        c.__name__ == "MujocoEnv" and c.__module__.startswith("gymnasium.envs.mujoco") for c in type(base).__mro__
    )


def adapt(env: gym.Env, failure=None) -> AdaptedEnv:
    """The risk adapter of ``env`` (see the module's table); ``failure(states) -> (N,) bool`` adds
    (or, for envs that never fail on their own, provides) the failure test.  ``TypeError`` names
    the env and what is missing when no adapter serves it."""
    base = env.unwrapped
    if isinstance(base, CartPoleEnv):
        return CartPoleAdapter(env, failure)
    if isinstance(base, PendulumEnv):
        return PendulumAdapter(env, failure)
    if _is_mujoco(base):
        # lazy: the MuJoCo adapters import mujoco (optional extra rmm-envs[mujoco]), loaded for a MuJoCo env only
        from rmm_envs.adapters.mujoco_envs import MujocoAdapter

        return MujocoAdapter(env, failure)
    try:
        check_labelled_env(env, needs=("risk_scene", "true_state"))
        lacks = f"{_env_name(env)} is not served by a risk adapter"
    except TypeError as e:
        lacks = str(e)
    raise TypeError(
        f"{lacks}; no risk adapter serves it either (adapters exist for {', '.join(SERVED)}); for a simulator of your own, "
        f"implement rmm_envs.adapters.SnapshotSimulator (get_state, set_state, step, state_failed, dt, action_space) "
        f"and label it through rmm_envs.adapters.SnapshotScene"
    )


def termination_is_failure(env: gym.Env) -> bool:
    """Whether ``env``'s own termination means failure, as the adapters know it (the "failure"
    column of the module's table: CartPole's termination, the unhealthy termination of the
    MuJoCo envs with a known failure test); False for any other env, including Pendulum (which
    never terminates) and envs whose termination may mean success."""
    base = env.unwrapped
    if not _is_mujoco(base):
        return isinstance(base, CartPoleEnv)
    # lazy: the MuJoCo adapters import mujoco (optional extra rmm-envs[mujoco]), loaded for a MuJoCo env only
    from rmm_envs.adapters.mujoco_envs import MujocoScene

    return type(base).__name__ in MujocoScene.KNOWN


def snapshot_of(adapter: AdaptedEnv):
    """The :class:`SnapshotSimulator` of an adapted env (steps the env itself, one at a time)."""
    if isinstance(adapter, (CartPoleAdapter, PendulumAdapter)):
        return ClassicControlSnapshot(adapter.env, adapter.scene)
    # lazy: the MuJoCo adapters import mujoco (optional extra rmm-envs[mujoco])
    from rmm_envs.adapters.mujoco_envs import MujocoAdapter, MujocoSnapshot

    if isinstance(adapter, MujocoAdapter):
        return MujocoSnapshot(adapter.env, adapter.scene)
    raise TypeError(f"no snapshot simulator for {type(adapter).__name__}")


def step_by_step(adapter: AdaptedEnv) -> SnapshotScene:
    """The step-by-step scene of an adapted env (the same failure test, the env's own ``step``
    called once per env step): the reference the batched scenes are tested and timed against."""
    s = adapter.scene
    return SnapshotScene(snapshot_of(adapter), name=s.name, failure=s.failure, default_horizon=s.default_horizon)
