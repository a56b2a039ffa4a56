"""The labelling hooks of :class:`rmm_envs.envs.any_env.GuardedAnyEnv` (the
:class:`rmm_envs.risk.LabelledEnv` protocol): the risk adapter's scene, state and observation,
and a state sampler that draws half of each batch from the adapter's own sampler and half from the
states the driver alone visits."""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np

from rmm_envs.adapters import adapt
from rmm_envs.adapters.base import AdaptedEnv
from rmm_envs.envs.given import as_policy, callable_name
from rmm_envs.envs.simulator import SnapshotAdapter, SnapshotEnv, require_hooks

__all__ = ["AnyEnvLabels"]


class AnyEnvLabels:
    """Mixed into :class:`rmm_envs.envs.any_env.GuardedAnyEnv`; reads its ``env``,
    ``simulator``, ``env_name``, ``_driver_obj``, ``_acts``, ``dt`` and ``max_episode_sim_time``."""

    env: Any
    simulator: Any
    env_name: str
    dt: float
    max_episode_sim_time: float
    _driver_obj: Any
    _acts: Any
    _failed: Callable[..., bool]
    _adapter: AdaptedEnv | None
    _sampler: tuple[gym.Env, AdaptedEnv] | None

    def _adapter_of(self, env: gym.Env, command: str | None = None) -> AdaptedEnv:
        if isinstance(env, SnapshotEnv):
            return SnapshotAdapter(env, command)
        return adapt(env)

    def _adapted(self) -> AdaptedEnv:
        if self._adapter is None:
            self._adapter = self._adapter_of(self.env)
        return self._adapter

    def require_labelling(self, command: str) -> None:
        """``TypeError`` naming ``command`` and the first hook it needs that the env lacks (a
        simulator of your own: ``state_failed``, ``sample_states``; another env: its risk adapter)."""
        if self.simulator is not None:
            require_hooks(self.simulator, ("state_failed", "sample_states"), command, self.env_name)
        self._adapted()

    @property
    def default_horizon(self) -> float:
        """The risk adapter's default horizon ``t`` (what ``rmm-datagen`` uses without ``--horizon``)."""
        return self._adapted().scene.default_horizon

    def risk_scene(self):
        self.require_episode()
        return self._adapted().scene

    @property
    def true_state(self) -> np.ndarray:
        return self._adapted().true_state

    def observe_states(self, states, rng=None) -> np.ndarray:
        return self._adapted().observe_states(states, rng)

    def privileged(self) -> dict:
        return self._adapted().privileged()

    def dataset_notes(self) -> dict:
        return self._adapted().dataset_notes()

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Half from the adapter's sampler, half from states the driver alone visits (see the module docstring)."""
        own = self._adapted().sample_states(rng, n // 2)
        return np.vstack([own, self._visited(rng, n - n // 2)])

    def _visited(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self._sampler is None:
            twin: gym.Env
            if isinstance(self.env, SnapshotEnv):
                twin = copy.deepcopy(self.env)  # the simulator copied, in its state when guarded() got it
            elif self.env.spec is None:
                raise TypeError(f"{self.env_name}: sampling visited states needs an env made by gym.make (a spec)")
            else:
                twin = gym.make(self.env.spec)
            self._sampler = (twin, self._adapter_of(twin))
        twin, adapter = self._sampler
        driver = copy.deepcopy(self._driver_obj)
        policy = as_policy(driver, "driver")
        # a simulator of one's own never truncates: its episodes end at max_episode_sim_time
        limit = math.ceil(self.max_episode_sim_time / self.dt - 1e-9) if isinstance(twin, SnapshotEnv) else math.inf
        pool: list[np.ndarray] = []
        while len(pool) < max(n, 1) * 2:
            obs, _ = twin.reset(seed=int(rng.integers(2**31)))
            begin = getattr(driver, "begin_episode", None)
            if callable(begin):
                begin(rng)
            pool.append(adapter.true_state)
            k = 0
            while k < limit:
                k += 1
                a = self._acts.check(policy(obs), f"the driver {callable_name(policy)}")
                obs, _, terminated, truncated, _ = twin.step(a)
                if self._failed(obs, terminated):
                    break
                pool.append(adapter.true_state)
                if terminated or truncated:
                    break
        states = np.array(pool)
        states = states[~adapter.scene.state_failed(states)]
        return states[rng.choice(states.shape[0], size=n, replace=states.shape[0] < n)]
