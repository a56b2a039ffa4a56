"""A safety filter of your own (docs/guardians.md): keep h = d - v^2 / (2 b) - margin >= 0.

    python docs/examples/braking_filter.py                 # one episode, as a library
    cd docs/examples && rmm-bench --agent braking_filter:BrakingFilter,inactive \
        --env Dubins4DGuarded-v0 --clock fixed:1 --episodes 64

``d`` is the shortest forward ray and ``b`` full braking, so the car can always stop.
``dh/dt + alpha h >= 0`` bounds the acceleration alone, so the minimal change of the driver's
control lowers ``u2`` and keeps its turn rate.  ``signals()`` puts ``h`` under the frames of a
replay, against its threshold 0.
"""

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from rmm_guardians.base import Guardian


class BrakingFilter(Guardian):
    """Keep h = d - v^2 / (2 b) - margin >= 0: d the shortest forward ray, b full braking."""

    name = "braking-filter"

    def __init__(self, alpha: float = 1.0, margin: float = 0.5) -> None:
        super().__init__()
        self.alpha, self.margin = alpha, margin
        self._h = float("nan")

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        lay = self.require_layout("rays", "speed")
        self.forward = [lay.ray_index(a) for a in (-np.pi / 6, 0.0, np.pi / 6)]
        self.speed = lay.index("speed")
        self.brake = -float(self.require_action_space(controls=2).control_low[1])

    def act(self, observation, info):
        u = np.array(info["nominal_control"])  # the driver's (turn rate, acceleration)
        d, v = float(min(observation[self.forward])), float(observation[self.speed])
        h = d - v * v / (2.0 * self.brake) - self.margin
        self._h = h
        if v > 0.0:
            u2_max = self.brake * (self.alpha * h - v) / v  # dh/dt + alpha h >= 0, for u2
            if u[1] > u2_max:
                u[1] = max(u2_max, -self.brake)
                return self.action_space.active(u)  # the minimal change: u2 only
        return self.action_space.inactive()  # the driver's control is safe: it keeps it

    def signals(self) -> dict[str, float]:
        return {"barrier": self._h, "barrier_threshold": 0.0}  # computed for the decision anyway


if __name__ == "__main__":
    env = gym.make("Dubins4DGuarded-v0", clock="fixed:1")
    guardian = BrakingFilter()
    obs, info = env.reset(seed=0)
    guardian.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    cost = 0.0
    while True:
        obs, reward, terminated, truncated, info = env.step(guardian.act(obs, info))
        cost += info["cost"]
        if terminated or truncated:
            break
    filtered = info["episode_stats"]["n_active_ctrl_env_steps"]
    print(info["outcome"], filtered, "steps filtered, cost", cost, "last signals", guardian.signals())
