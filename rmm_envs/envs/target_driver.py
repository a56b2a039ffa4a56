"""A cart and pole driven to a target position: :class:`TargetDriver`, the driver, success test
and safe default of the target task (described by ``CartPoleGuarded-v0``'s page,
docs/environments/driven_examples.md), and :func:`target_task_env`, a guarded env of that task
around a Gymnasium env of a cart and pole.  Each system of that task (its gains, distances and
time limit) is a folder: ``rmm_envs/systems/cartpole``, ``rmm_envs/systems/pendulum``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rmm_envs.envs.any_env import guarded

__all__ = ["TargetDriver", "target_task_env"]


@dataclass
class TargetDriver:
    """The reckless driver of a cart-and-pole target task, with its success test and its safe
    default (:meth:`balance`): the built-in ``CartPole`` and ``InvertedPendulum`` systems' driver
    (their task: ``rmm_envs/systems/cartpole/guarded.py``).

    ``pos`` and ``ang`` are where the cart position and the pole angle sit in the observation,
    ``k`` the balancing gains over the observation, ``discrete``: the env takes push left/right.
    """

    k: tuple
    pos: int
    ang: int
    dt: float
    near: float
    far: float
    g_lo: float
    g_hi: float
    tol_x: float
    hold: float
    discrete: bool
    force: float = 3.0
    target: float = 0.0
    gain: float = 1.0
    _held: int = 0

    def begin_episode(self, rng: np.random.Generator) -> None:
        self.target = float(rng.choice((-1.0, 1.0)) * rng.uniform(self.near, self.far))
        self.gain = float(rng.uniform(self.g_lo, self.g_hi))
        self._held = 0

    def control(self, obs, target: float, gain: float):
        s = np.asarray(obs, dtype=float)
        u = 0.0
        for i, k in enumerate(self.k):  # -K (s - s*), the position gain times `gain`
            e = s[i] - target if i == self.pos else s[i]
            u -= (gain * k if i == self.pos else k) * e
        if self.discrete:
            return 1 if u > 0 else 0
        return np.array([min(max(u, -self.force), self.force)], dtype=np.float32)

    def __call__(self, obs):
        return self.control(obs, self.target, self.gain)

    def balance(self, obs):
        """The safe default: balance at the centre of the track."""
        return self.control(obs, 0.0, 1.0)

    def reached(self, obs) -> bool:
        ok = abs(float(obs[self.pos]) - self.target) < self.tol_x and abs(float(obs[self.ang])) < 0.05
        self._held = self._held + 1 if ok else 0
        return self._held * self.dt >= self.hold - 1e-9


def target_task_env(env_id: str, driver: TargetDriver, max_episode_sim_time: float, /, clock=None, **kwargs):
    """The blocking guarded env of the Gymnasium env ``env_id`` under the target task: ``driver``
    drives, its :meth:`~TargetDriver.balance` is the safe default and
    :meth:`~TargetDriver.reached` the success test (keywords as :func:`rmm_envs.envs.any_env.guarded`;
    a ``max_episode_sim_time`` among them, as ``gym.make`` passes it, overrides the system's)."""
    defaults = {"controls": ("force_ctrl",), "max_episode_sim_time": max_episode_sim_time}
    return guarded(
        env_id, driver=driver, safe_default=driver.balance, success=driver.reached, clock=clock, **(defaults | kwargs)
    )
