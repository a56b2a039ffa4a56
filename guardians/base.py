"""The Guardian protocol: what a guardian is to the benchmark and to users.

A guardian watches a driver and decides, each step, whether to take control and with which
control.  It has:

* ``name``: a short identifier (used in result tables);
* ``observation_type``: ``"local"`` (uses only the env's observation), ``"global"`` (needs
  privileged information: the true state and the obstacle geometry) or ``"none"``;
* ``privileged`` (bool): whether :meth:`reset` must be given the env's privileged accessor;
* :meth:`reset` at the start of every episode, with the episode's seed, the env's spaces and,
  for privileged guardians, ``privileged``: a zero-argument callable returning the env's
  documented privileged data (``Dubins4DCirclesEnv.privileged()``: true ``state``,
  ``obstacles``, ``goal``, ``sim_time``).  Guardians never read private attributes of an env;
* :meth:`act` ``(observation, info) -> action`` in the env's action space, a dict
  ``{"active_ctrl": 0/1, "turnrate_ctrl": (1,), "accel_ctrl": (1,)}`` for the Dubins4D envs;
* ``stats()``: counters the guardian wants recorded with the episode (e.g. QP fallbacks).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

__all__ = ["Guardian", "active_action", "inactive_action"]


def inactive_action() -> dict:
    """Let the driver control this step."""
    return {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}


def active_action(turnrate: float, accel: float) -> dict:
    """Take control and apply ``(turnrate, accel)``."""
    return {"active_ctrl": 1, "turnrate_ctrl": np.array([turnrate], np.float32), "accel_ctrl": np.array([accel], np.float32)}


class Guardian:
    """Base class; subclasses override :meth:`act` (and :meth:`reset` when they keep state)."""

    name: str = "guardian"
    observation_type: str = "local"
    privileged: bool = False

    def __init__(self) -> None:
        self.observation_space = None
        self.action_space = None
        self.rng = np.random.default_rng()
        self._privileged: Callable[[], dict] | None = None

    def reset(self, *, seed: int | None = None, observation_space=None, action_space=None,
              privileged: Callable[[], dict] | None = None) -> None:
        self.observation_space = observation_space
        self.action_space = action_space
        self.rng = np.random.default_rng(seed)
        if self.privileged and privileged is None:
            raise ValueError(f"guardian {self.name!r} needs privileged information: pass reset(privileged=env.unwrapped.privileged)")
        self._privileged = privileged

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError

    def stats(self) -> dict[str, float]:
        return {}

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"
