"""The LRMM guardian: take control when the learned risk of the local observation is high.

Each step: ``risk = model(observation)`` (numpy, local observation only, no privileged data).
If ``risk > threshold`` (0.85) the guardian takes control with maximum braking and a maximum
turn toward the more open side, comparing the +30 and -30 degree rays (no turn when they are
equal within ``numpy.isclose``); control returns to the driver once the risk is back at or
below the threshold.  This avoidance control is the paper's heuristic: the LRMM says *when*
to act, not *what* to do.

``hysteresis=True`` reproduces the original code's release rule: a deque of the last ``window``
(20) risks, initialised at the threshold, and the guardian intervenes while either the current
risk or the deque's mean exceeds the threshold (REFERENCE section 2.1).
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import numpy as np

from guardians.base import Guardian, active_action, inactive_action
from guardians.lrmm.model import LRMMModel, load_model

__all__ = ["LRMMGuardian"]


class LRMMGuardian(Guardian):
    """Args:
        model: an :class:`LRMMModel`, a model file path, or ``None`` for the shipped model.
        threshold: risk above which the guardian takes control (default 0.85).
        hysteresis: use the original's moving-average release rule (default False).
        window: moving-average length with ``hysteresis`` (default 20).
        u1_max, u2_min: the turn rate and braking applied when in control (0.25, -0.5).
    """

    name = "lrmm"
    observation_type = "local"
    privileged = False

    def __init__(self, model: LRMMModel | str | Path | None = None, threshold: float = 0.85,
                 hysteresis: bool = False, window: int = 20, u1_max: float = 0.25, u2_min: float = -0.5) -> None:
        super().__init__()
        if not 0.0 <= threshold <= 1.0:
            raise ValueError(f"threshold must be in [0, 1], got {threshold}")
        if int(window) != window or window < 1:
            raise ValueError(f"window must be an integer >= 1, got {window}")
        self.model = model if isinstance(model, LRMMModel) else load_model(model)
        self.threshold = float(threshold)
        self.hysteresis = bool(hysteresis)
        self.window = int(window)
        self.u1_max = float(u1_max)
        self.u2_min = float(u2_min)
        self._history: deque = deque(maxlen=self.window)
        self.last_risk = float("nan")
        n_rays = self.model.obs_dim - 5
        self._left, self._right = 5 + 1, 5 + n_rays - 1  # +30 and -30 degree rays (12 rays)

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        space = kwargs.get("observation_space")
        if space is not None and space.shape != (self.model.obs_dim,):
            raise ValueError(
                f"the LRMM model expects observations of shape ({self.model.obs_dim},), "
                f"the env's observation space is {space.shape}"
            )
        self._history = deque([self.threshold] * self.window, maxlen=self.window)
        self.last_risk = float("nan")

    def risk(self, observation) -> float:
        return self.model.predict(observation)

    def act(self, observation, info=None):
        risk = self.model.predict(observation)
        self.last_risk = risk
        intervene = risk > self.threshold
        if self.hysteresis:
            self._history.append(risk)
            intervene = intervene or (sum(self._history) / len(self._history) > self.threshold)
        if not intervene:
            return inactive_action()
        left, right = observation[self._left], observation[self._right]
        if np.isclose(left, right):
            turn = 0.0
        elif left > right:
            turn = self.u1_max
        else:
            turn = -self.u1_max
        return active_action(turn, self.u2_min)
