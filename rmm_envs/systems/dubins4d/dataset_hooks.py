"""The dataset hooks of the Dubins4D env (:class:`rmm_envs.risk.LabelledEnv`'s): states drawn over
the arena and observed as the env observes them, for risk labels."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.envs.base import rejection_sample
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.dubins4d.starts import HALF as _HALF

__all__ = ["Dubins4DDatasetHooks"]


class Dubins4DDatasetHooks:
    """``sample_states``, ``observe_states`` and ``dataset_notes`` of
    :class:`rmm_envs.systems.dubins4d.env.Dubins4DGuardedEnv` (it sets ``scene``, ``dynamics`` and
    ``max_episode_sim_time``)."""

    scene: Any
    dynamics: Dubins4D
    max_episode_sim_time: float
    require_episode: Callable[[], None]

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` states uniform over the arena x [-pi, pi) x [0, 2], outside every obstacle
        (rejection sampling, as the original's datagen since 2022-09-13)."""
        self.require_episode()
        assert self.scene is not None  # require_episode raised otherwise
        s = self.dynamics
        return rejection_sample(
            rng,
            n,
            4,
            lambda r, m: np.column_stack(
                [
                    r.uniform(-_HALF, _HALF, m),
                    r.uniform(-_HALF, _HALF, m),
                    r.uniform(-np.pi, np.pi, m),
                    r.uniform(s.v_min, s.v_max, m),
                ]
            ),
            self.scene.state_failed,
            "states outside the obstacles",
        )

    def observe_states(self, states: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Observations of arbitrary states for a dataset.  The simulated-time feature is drawn
        from ``rng`` (required) uniformly over the episode range ``[0, max_episode_sim_time]``: the
        original left it 0 in every training sample and met 0-100 s at run time
        (docs/original-code.md, item 8)."""
        self.require_episode()
        if not isinstance(rng, np.random.Generator):
            raise ValueError(
                f"observe_states needs rng, a numpy.random.Generator to draw the simulated-time feature, got {rng!r}"
            )
        t = rng.uniform(0.0, self.max_episode_sim_time, size=np.asarray(states).shape[0])
        assert self.scene is not None  # require_episode raised otherwise
        return self.scene.observe(states, t)

    def dataset_notes(self) -> dict:
        return {"obs_time_feature": "uniform over [0, max_episode_sim_time]"}
