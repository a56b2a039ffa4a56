"""The base of privileged guardians (``cbf`` and ``hj`` on every system): what they share.

:class:`PrivilegedGuardian` is a :class:`rmm_guardians.base.Guardian` that reads the env's privileged
data (``observation_type = "global"``, ``privileged = True``) and owns:

* the lap measurement: the simulated time between consecutive decisions, read from the
  privileged ``sim_time`` (:meth:`start_laps` at reset, :meth:`measure_lap` or
  :meth:`_state_and_lap` at each decision, :meth:`current_lap` for the lap a rule assumes);
* the guard against a privileged state that is not finite (or not of the expected size):
  :meth:`finite_state` says so and counts it in the guardian's ``nan_states`` counter, and the
  guardian then applies its system's safe control.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rmm_guardians.base import Guardian

__all__ = ["DEFAULT_LAP", "PrivilegedGuardian"]

#: The lap (s) a rule assumes before one is measured: the environments' default base step.
DEFAULT_LAP = 0.1


class PrivilegedGuardian(Guardian):
    """A guardian of privileged data; subclasses keep a ``self._counts`` dict with ``"nan_states"``."""

    observation_type = "global"
    privileged = True
    #: a fixed lap (s) the rule assumes instead of the measured one (``None``: measure)
    lap: float | None = None
    _last_time: float | None = None  # the sim time of the previous measurement (None: none yet)
    _measured_lap: float | None = None  # the last lap measured, or the guess before one
    _counts: dict[str, int]  # set by each subclass's constructor and reset (``"nan_states"`` among them)

    def start_laps(self, guess: float | None = None, since: float | None = None) -> None:
        """Start measuring laps (at reset): ``since`` is the sim time the first lap counts from
        (``None``: the first decision's, so the first lap is measured at the second), ``guess``
        the lap assumed until one is measured."""
        self._last_time = None if since is None else float(since)
        self._measured_lap = guess

    def measure_lap(self, priv: dict[str, Any]) -> None:
        """Measure the lap from ``priv["sim_time"]``: the time since the previous measurement,
        kept only when time advanced; nothing moves when the env reports no time."""
        t = priv.get("sim_time")
        if t is not None:
            last = self._last_time
            if last is not None and t > last:
                self._measured_lap = float(t - last)
            self._last_time = float(t)

    def _state_and_lap(self) -> np.ndarray:
        """The env's privileged ``state`` as floats, after measuring the lap (:meth:`measure_lap`)."""
        assert self._privileged is not None  # reset refuses a privileged guardian without it
        priv = self._privileged()
        self.measure_lap(priv)
        return np.asarray(priv["state"], float)

    def current_lap(self) -> float:
        """The lap length the rule assumes: :attr:`lap` if given, else the last one measured
        (:data:`DEFAULT_LAP` before any)."""
        if self.lap is not None:
            return self.lap
        return self._measured_lap if self._measured_lap is not None else DEFAULT_LAP

    def finite_state(self, state: np.ndarray, size: int | None = None) -> bool:
        """Whether the privileged ``state`` can be decided on: every number finite (and ``size``
        numbers when given); one that cannot is counted in ``self._counts["nan_states"]``."""
        ok = (size is None or state.shape == (size,)) and bool(np.isfinite(state).all())
        if not ok:
            self._counts["nan_states"] += 1
        return ok
