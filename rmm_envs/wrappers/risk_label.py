"""RiskLabel: add the sampling-tree risk of the current true state to ``info["risk"]``.

Works on any environment whose unwrapped env offers the ``risk_scene()`` and ``true_state``
hooks of the :class:`rmm_envs.risk.LabelledEnv` protocol (checked at construction by
:func:`rmm_envs.risk.check_labelled_env`, which names what is missing).  At ``reset`` and
after every ``step`` it runs the estimator on the true state and adds:

* ``info["risk"]``: the risk metric (float in [0, 1]);
* ``info["risk_min_ctrl"]``: the first control of the minimum-risk branch;
* ``info["risk_n_leaves"]``: the number of terminal nodes behind the estimate.

The labelling time is real CPU work done between the inner ``step`` returning and this
wrapper returning: wrap *inside* a non-blocking wrapper (or use a fixed clock) if it must not
be charged as the agent's thinking time.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

from rmm_envs.risk.estimator import RiskEstimator, validate_tree_params
from rmm_envs.risk.protocol import check_labelled_env

__all__ = ["RiskLabel"]


class RiskLabel(gym.Wrapper):
    """Args: ``branches`` (n), ``depth`` (m), ``horizon`` (t, s), ``n_steps``, ``metric``
    (``expected``/``cvar``/``worst``), ``alpha`` (for cvar), ``leaf`` (``zero``/``heuristic``),
    ``seed`` (for the estimator's own generator; ``None``: fresh entropy)."""

    def __init__(self, env: gym.Env, branches: int = 32, depth: int = 2, horizon: float = 2.0,
                 n_steps: int = 8, metric: str = "expected", alpha: float | None = None,
                 leaf: str = "zero", seed: int | None = None):
        super().__init__(env)
        check_labelled_env(env, needs=("risk_scene", "true_state"))
        self._kw = dict(branches=branches, depth=depth, horizon=horizon, n_steps=n_steps,
                        metric=metric, alpha=alpha, leaf=leaf)
        validate_tree_params(**self._kw)  # now, not at the first reset
        self.rng = np.random.default_rng(seed)
        self._estimator = None
        self._scene = None

    def _label(self, info: dict) -> dict:
        base = self.env.unwrapped
        scene = base.risk_scene()
        if scene is not self._scene:
            self._scene = scene
            self._estimator = RiskEstimator(scene, **self._kw)
        res = self._estimator.estimate(np.asarray(base.true_state, dtype=float)[None, :], self.rng)
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
