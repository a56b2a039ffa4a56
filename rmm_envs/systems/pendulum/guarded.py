"""The ``InvertedPendulum`` system: Gymnasium's MuJoCo ``InvertedPendulum-v5`` (extra ``mujoco``)
under the target task of ``CartPole`` (:mod:`rmm_envs.systems.cartpole.guarded`, whose docstring
describes both), as ``InvertedPendulumGuarded-v0`` and its non-blocking twin
``InvertedPendulumParallel-v0`` (one env step, 0.04 s, per base step)."""

from __future__ import annotations

from rmm_envs.envs.guarded import parallel_twin
from rmm_envs.envs.target_driver import TargetDriver, target_task_env

__all__ = ["PENDULUM_K", "driver", "guarded_env", "parallel_env"]

#: InvertedPendulum's balancing gains (state ``(x, theta, x_dot, theta_dot)``; see rmm_envs.systems.cartpole.guarded)
PENDULUM_K = (-0.72237285, -6.830044, -0.92326489, -1.08445913)


def driver() -> TargetDriver:
    """A new driver of InvertedPendulum's target task (its gains, distances and tolerances)."""
    return TargetDriver(
        PENDULUM_K, pos=0, ang=1, dt=0.04, near=0.3, far=0.8, g_lo=1.0, g_hi=4.0, tol_x=0.1, hold=1.0, discrete=False
    )


def guarded_env(clock=None, **kwargs):
    """Entry point of ``InvertedPendulumGuarded-v0`` (keywords as :func:`rmm_envs.envs.any_env.guarded`)."""
    return target_task_env("InvertedPendulum-v5", driver(), 10.0, clock=clock, **kwargs)


#: Entry point of ``InvertedPendulumParallel-v0``: ``InvertedPendulumGuarded-v0`` stepped non-blocking,
#: one env step (0.04 s) per base step.
parallel_env = parallel_twin(guarded_env, "InvertedPendulumParallel-v0", 0.04)
