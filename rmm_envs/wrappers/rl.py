"""Wrappers for training guardians with reinforcement-learning libraries.

For every env whose action space is an :class:`rmm_envs.autonomy.GuardianActionSpace`:

:class:`FlattenGuardianAction`
    Action space ``Box(-1, 1, (1 + c,), float32)`` for ``c`` controls: ``a[0] > 0.5`` takes
    control, ``a[1:]`` are the controls scaled to the env's bounds;
    :meth:`FlattenGuardianAction.to_guardian` converts such a vector back.
:class:`GuardianReward`
    ``r = goal_bonus * [reached the goal] - collision_penalty * [collided]
    - intervention_cost * (simulated seconds under guardian control this step)``, defaults
    1, 10 and 0.05 per second; the env's own reward is kept in ``info["env_reward"]``.

Why these conventions and these weights: :class:`FlattenGuardianAction`, :class:`GuardianReward`.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from rmm_envs.autonomy import GuardianActionSpace

__all__ = ["FlattenGuardianAction", "GuardianReward"]


def _guardian_space(env: gym.Env, wrapper: str) -> GuardianActionSpace:
    space = env.action_space
    if not isinstance(space, GuardianActionSpace):
        raise TypeError(
            f"{wrapper} needs a parallel-autonomy env (action space rmm_envs.autonomy.GuardianActionSpace); "
            f"{env.unwrapped.spec.id if env.unwrapped.spec else type(env.unwrapped).__name__} has {space}"
        )
    return space


class FlattenGuardianAction(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """The guardian action as ``Box(-1, 1, (1 + c,))``; see the module docstring.

    Most RL libraries train on ``Box`` or ``Discrete`` actions, not on a ``Dict``.  A symmetric
    unit box is what Stable-Baselines3's PPO and SAC expect; ``a[0] > 0.5`` takes control, so a
    policy that outputs zeros (a fresh Gaussian policy, on average) leaves the driver in charge;
    ``-1`` is each control's lower and ``+1`` its upper bound (values outside ``[-1, 1]`` are
    clipped first).  The mapping is :meth:`rmm_envs.autonomy.GuardianActionSpace.from_unit`, which
    :class:`rmm_guardians.SB3Guardian` also reads, so a policy trained through this wrapper applies
    the same controls when benchmarked.  Non-finite values raise ``ValueError`` naming the index."""

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.ActionWrapper.__init__(self, env)
        self.guardian_space = _guardian_space(env, "FlattenGuardianAction")
        n = 1 + self.guardian_space.control_dim
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)

    @staticmethod
    def to_guardian(space: GuardianActionSpace, action) -> dict:
        """The guardian action of ``space`` for a flat vector ``[active, scaled controls...]``:
        :meth:`rmm_envs.autonomy.GuardianActionSpace.from_unit`, the one mapping this wrapper
        and :class:`rmm_guardians.wrapped.SB3Guardian` share."""
        return space.from_unit(action)

    def action(self, action) -> dict:
        return self.to_guardian(self.guardian_space, action)


class GuardianReward(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Shaped reward for training guardians; see the module docstring.

    The env's own reward (+1 goal, -1 collision) says nothing about the cost of taking control.
    The penalty is ten times the bonus because a guardian's purpose is to prevent crashes; a
    guardian that takes control for a whole 100 s episode pays 5, half a crash, so holding the
    brakes for ever is worse than intervening briefly but still better than crashing.  The
    intervention cost is charged per simulated second, not per step, because non-blocking steps
    have different lengths.  ``info["episode_stats"]`` is unchanged; the three weights must be
    finite and ``>= 0``."""

    def __init__(
        self, env: gym.Env, goal_bonus: float = 1.0, collision_penalty: float = 10.0, intervention_cost: float = 0.05
    ) -> None:
        gym.utils.RecordConstructorArgs.__init__(
            self, goal_bonus=goal_bonus, collision_penalty=collision_penalty, intervention_cost=intervention_cost
        )
        gym.Wrapper.__init__(self, env)
        _guardian_space(env.unwrapped, "GuardianReward")
        for name, v in (
            ("goal_bonus", goal_bonus),
            ("collision_penalty", collision_penalty),
            ("intervention_cost", intervention_cost),
        ):
            if (
                isinstance(v, bool)
                or not isinstance(v, (int, float, np.integer, np.floating))
                or not (math.isfinite(v) and v >= 0)
            ):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
        self.goal_bonus = float(goal_bonus)
        self.collision_penalty = float(collision_penalty)
        self.intervention_cost = float(intervention_cost)
        self._sim_time = 0.0

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._sim_time = float(info.get("sim_time", 0.0))
        return obs, info

    def step(self, action):
        obs, env_reward, terminated, truncated, info = self.env.step(action)
        now = float(info["sim_time"])
        dt, self._sim_time = now - self._sim_time, now
        outcome = info.get("outcome")
        reward = -self.intervention_cost * dt if info.get("active") else 0.0
        if outcome == "goal":
            reward += self.goal_bonus
        elif outcome == "collision":
            reward -= self.collision_penalty
        info = {**info, "env_reward": env_reward}
        return obs, float(reward), terminated, truncated, info
