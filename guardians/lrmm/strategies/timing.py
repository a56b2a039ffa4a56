"""Strategies that change only *when* the guardian is in control: :class:`Commit` and
:class:`MovingAverage`."""

from __future__ import annotations

from collections import deque

from rmm_guardians._checks import integer
from rmm_guardians.lrmm.strategies.base import DecisionContext, Strategy

__all__ = ["Commit", "MovingAverage"]


class MovingAverage(Strategy):
    """Also in control while the mean risk of the last ``window`` decisions is above the
    threshold (the window starts full of the threshold).  Why: the original code's release rule,
    kept to reproduce it."""

    PARAMS = ("window",)

    def __init__(self, window: int = 20) -> None:
        self.window = integer("MovingAverage window", window, 1)

    def reset(self, guardian) -> None:
        self._history = deque([guardian.threshold] * self.window, maxlen=self.window)

    def take(self, step: DecisionContext, take: bool) -> bool:
        self._history.append(step.risk)
        return take or sum(self._history) / len(self._history) > step.threshold


class Commit(Strategy):
    """Stay in control ``steps`` decisions after the verdict before it turns to "not in control".

    Why: a risk hovering at the threshold hands control back and forth every step, and the
    driver, handed a car half way through an avoidance, steers it back into danger."""

    PARAMS = ("steps",)

    def __init__(self, steps: int = 0) -> None:
        self.steps = integer("Commit steps", steps, 0, "decisions to stay in control")
        self._left = 0

    def reset(self, guardian) -> None:
        self._left = 0

    def take(self, step: DecisionContext, take: bool) -> bool:
        if take:
            self._left = self.steps
        elif self._left > 0:
            self._left -= 1
            return True
        return take
