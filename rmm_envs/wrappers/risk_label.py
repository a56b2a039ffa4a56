"""RiskLabel: add the sampling-tree risk of the current true state to ``info["risk"]``.

Works on any environment whose unwrapped env offers the ``risk_scene()`` and ``true_state``
hooks of the :class:`rmm_envs.risk.LabelledEnv` protocol, and on the envs a risk adapter of
:mod:`rmm_envs.adapters` serves; any other env is refused at construction with a ``TypeError``
naming it and what is missing.  At ``reset`` and after every ``step`` it runs the estimator on
the true state and adds ``info["risk"]`` (the risk metric, in [0, 1]), ``info["risk_min_ctrl"]``
(the first control of the minimum-risk branch; for a ``Discrete`` action space a value ``u``
meaning action ``floor(u)``) and ``info["risk_n_leaves"]`` (the terminal nodes behind it).

The labelling time is real CPU work done between the inner ``step`` returning and this
wrapper returning: wrap *inside* a non-blocking wrapper (or use a fixed clock) if it must not
be charged as the agent's thinking time.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from rmm_envs.adapters import adapt
from rmm_envs.risk.estimator import RiskEstimator, validate_tree_params
from rmm_envs.risk.protocol import check_labelled_env

__all__ = ["RiskLabel"]


class RiskLabel(gym.Wrapper):
    """Args: ``branches`` (n), ``depth`` (m), ``horizon`` (t, s), ``n_steps``, ``metric``
    (``expected``/``cvar``/``worst``), ``alpha`` (for cvar), ``leaf`` (``zero``/``heuristic``),
    ``seed`` (for the estimator's own generator; ``None``: fresh entropy), ``failure`` (only for
    an adapted env: ``failure(states (N, d)) -> (N,) bool``, added to the adapter's own test).
    ``horizon=None`` (default) is 2 s for the package's envs and the adapter's own default for
    an adapted env (a whole number of its steps, see :mod:`rmm_envs.adapters`)."""

    def __init__(
        self,
        env: gym.Env,
        branches: int = 32,
        depth: int = 2,
        horizon: float | None = None,
        n_steps: int = 8,
        metric: str = "expected",
        alpha: float | None = None,
        leaf: str = "zero",
        seed: int | None = None,
        failure=None,
    ):
        super().__init__(env)
        adapted = None
        # the labelling hooks: the unwrapped env (a LabelledEnv) or the adapter serving it
        self._hooks: Any
        try:
            check_labelled_env(env, needs=("risk_scene", "true_state"))
            self._hooks = self.env.unwrapped
        except TypeError:
            self._hooks = adapted = adapt(env, failure)
        else:
            if failure is not None:
                raise TypeError(
                    f"failure= is for envs served by a risk adapter (rmm_envs.adapters); "
                    f"{type(self._hooks).__name__} defines its own failures in its risk_scene()"
                )
        if horizon is None:
            horizon = 2.0 if adapted is None else adapted.scene.default_horizon
        self._kw: dict[str, Any] = dict(
            branches=branches, depth=depth, horizon=horizon, n_steps=n_steps, metric=metric, alpha=alpha, leaf=leaf
        )
        validate_tree_params(**self._kw)  # now, not at the first reset
        if adapted is not None:  # its horizon must be whole env steps
            adapted.scene.env_steps(self._kw["horizon"])
        self.rng = np.random.default_rng(seed)
        self._estimator: RiskEstimator | None = None
        self._scene: object | None = None

    def _label(self, info: dict) -> dict:
        base = self._hooks
        scene = base.risk_scene()
        estimator = self._estimator
        if estimator is None or scene is not self._scene:
            self._scene = scene
            self._estimator = estimator = RiskEstimator(scene, **self._kw)
        res = estimator.estimate(np.asarray(base.true_state, dtype=np.float64)[None, :], self.rng)
        info = dict(info)
        info["risk"] = float(res.risk[0])
        info["risk_min_ctrl"] = res.min_risk_ctrl[0]
        info["risk_n_leaves"] = int(res.n_leaves[0])
        return info

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, self._label(info)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward, terminated, truncated, self._label(info)
