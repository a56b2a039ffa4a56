"""One step of :class:`rmm_envs.systems.dubins4d.vector.Dubins4DCirclesVectorEnv` under disturbances,
each sub-env exactly as the single env with its seed applies them (:mod:`rmm_envs.disturbances`)."""

from __future__ import annotations

import numpy as np

from rmm_envs.disturbances.rows import control_rows, rate_rows
from rmm_envs.systems.dubins4d.step import advance

__all__ = ["advance_disturbed"]


def advance_disturbed(self, active: np.ndarray, ctrl: np.ndarray):
    """:func:`advance` under each sub-env's disturbances, as the single env applies them: the
    actuators' controls, the plant's gains and the position drift, all rows at once, in one batch
    also when a mismatch gives the rows plants of their own (each row's path under its plant's
    bounds, the operations of the single env's own batch of one)."""
    e, n = self._single, self.num_envs
    draws, times = self._draws, self._sim_time
    commanded = np.where(active[:, None], ctrl, self._nominal)
    applied = control_rows(draws, commanded, times, self._streams)
    rates = rate_rows(draws, times, 4, self._streams) if draws[0].pushes else None
    on = np.ones(n, dtype=bool)
    controls = applied * self._gains
    mismatch = any(d.kind == "mismatch" for d in e.disturbances)
    plants = self._plants if mismatch else e.dynamics  # a mismatch: each row's plant its own bounds
    out = advance(plants, self._nominal, self._states, self._circles, on, controls, e._step_times, None, rates)
    return out[0], applied, out[2], out[3]
