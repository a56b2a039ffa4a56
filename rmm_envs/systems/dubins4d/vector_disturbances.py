"""One step of :class:`rmm_envs.systems.dubins4d.vector.Dubins4DCirclesVectorEnv` under disturbances,
each sub-env exactly as the single env with its seed applies them (:mod:`rmm_envs.disturbances`)."""

from __future__ import annotations

import numpy as np

from rmm_envs.disturbances.realisation import control_rows, rate_rows
from rmm_envs.systems.dubins4d.step import advance

__all__ = ["advance_disturbed"]


def advance_disturbed(self, active: np.ndarray, ctrl: np.ndarray):
    """:func:`advance` under each sub-env's disturbances, as the single env applies them: the
    actuators' controls, the plant's gains and the position drift, all rows at once; one batch
    unless a mismatch gives the rows plants of their own (then row by row, each as the single
    env's own batch of one)."""
    e, n = self._single, self.num_envs
    draws, times = self._draws, self._sim_time
    commanded = np.where(active[:, None], ctrl, self._nominal)
    applied = control_rows(draws, commanded, times)
    rates = rate_rows(draws, times, 4) if draws[0].pushes else None
    on = np.ones(n, dtype=bool)
    controls = applied * self._gains
    if not any(d.kind == "mismatch" for d in e.disturbances):
        out = advance(e.dynamics, self._nominal, self._states, self._circles, on, controls, e._step_times, None, rates)
    else:
        rows = [
            advance(
                self._plants[i],
                self._nominal[i : i + 1],
                self._states[i : i + 1],
                self._circles[i : i + 1],
                on[i : i + 1],
                controls[i : i + 1],
                e._step_times,
                None,
                None if rates is None else rates[i : i + 1],
            )  # fmt: skip
            for i in range(n)
        ]
        out = tuple(np.concatenate([r[j] for r in rows]) for j in range(4))
    return out[0], applied, out[2], out[3]
