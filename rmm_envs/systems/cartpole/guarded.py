"""The ``CartPole`` system, and the target task it shares with ``InvertedPendulum``: two guarded
envs built with :func:`rmm_envs.envs.any_env.guarded` around simulators the project did not write:
``CartPoleGuarded-v0`` (Gymnasium's ``CartPole-v1``) and
``InvertedPendulumGuarded-v0`` (Gymnasium's MuJoCo ``InvertedPendulum-v5``, extra ``mujoco``),
with their non-blocking twins ``CartPoleParallel-v0`` and ``InvertedPendulumParallel-v0``.

Both are the same task: **drive the cart to a target position and hold it there with the pole
up**.  Each episode draws the target ``x*`` (uniform in ``+-[near, far]`` m, away from the start
at the centre) and the driver's aggressiveness ``g`` (uniform in ``[g_lo, g_hi]``).

Observation
    The env's own: ``(x, x_dot, theta, theta_dot)`` for CartPole, ``(x, theta, x_dot,
    theta_dot)`` for InvertedPendulum (``float32``, ``float64``).  The target is the driver's,
    not observed: the guardian reads the system's state only.
Guardian action
    ``{"active_ctrl": 0 or 1, "force_ctrl": shape-(1,)}``: CartPole's ``Discrete(2)`` as the
    control box ``[0, 2]`` (``floor``: below 1 pushes left, from 1 pushes right);
    InvertedPendulum's force in ``[-3, 3]``.
Driver (reckless)
    The balancing controller below steered at the target with its position gain multiplied by
    ``g`` and the position error unclipped: far targets make it push hard and long, and the
    pole falls or (CartPole) the cart leaves the track in a fair share of episodes.  CartPole:
    push right when ``g k_x (x - x*) + k_v x_dot + k_t theta + k_w theta_dot > 0``;
    InvertedPendulum: the force ``clip(-K (s - s*), -3, 3)`` with the position entry of ``K``
    times ``g``.
Safe default
    The balancing controller itself, regulating to the track's centre (``x* = 0``, ``g = 1``):
    an LQR of the linearised dynamics (CartPole: the continuous-time LQR of the env's
    equations, ``Q = diag(1, 1, 10, 1)``, ``R = 0.1``, applied as the sign of the force;
    InvertedPendulum: the discrete-time LQR of the env's own step linearised by finite
    differences, ``Q = diag(1, 10, 0.1, 0.1)``, ``R = 1``).  It rarely fails and never reaches
    a target, all of them being away from the centre.
Success (``"goal"``)
    ``|x - x*| < tol_x`` and ``|theta| < 0.05`` rad for ``hold`` seconds in a row.
Failure (``"collision"``)
    The env's termination: CartPole's ``|x| > 2.4`` or ``|theta| > 12`` deg, InvertedPendulum's
    ``|theta| > 0.2`` rad.
Timeout
    ``max_episode_sim_time``: 10 s (CartPole's own limit, 500 steps) and 10 s (250 of
    InvertedPendulum's 0.04 s steps).
Parallel twins
    The same under :class:`rmm_envs.wrappers.NonBlockingStepping` with ``base_step`` one env
    step (0.02 s, 0.04 s) and ``time_accel`` 10.

Both are systems of the table :data:`rmm_envs.catalog.SYSTEMS` (``CartPole`` and ``InvertedPendulum``),
each a folder (``rmm_envs/systems/cartpole``, ``rmm_envs/systems/pendulum``); their driver is
:class:`rmm_envs.envs.target_driver.TargetDriver`.
"""

from __future__ import annotations

from rmm_envs.envs.guarded import parallel_twin
from rmm_envs.envs.target_driver import TargetDriver, target_task_env

__all__ = ["CARTPOLE_K", "driver", "guarded_env", "parallel_env"]

#: CartPole's balancing gains: ``u = -K s`` of the continuous-time LQR (see the module docstring)
CARTPOLE_K = (-3.16227766, -5.91549435, -49.50716842, -12.84439629)


def driver() -> TargetDriver:
    """A new driver of CartPole's target task (its gains, distances and tolerances)."""
    return TargetDriver(
        CARTPOLE_K, pos=0, ang=2, dt=0.02, near=0.6, far=1.8, g_lo=1.0, g_hi=4.0, tol_x=0.2, hold=1.0, discrete=True
    )


def guarded_env(clock=None, **kwargs):
    """Entry point of ``CartPoleGuarded-v0`` (keywords as :func:`rmm_envs.envs.any_env.guarded`)."""
    return target_task_env("CartPole-v1", driver(), 10.0, clock=clock, **kwargs)


#: Entry point of ``CartPoleParallel-v0``: ``CartPoleGuarded-v0`` stepped non-blocking, one env step (0.02 s) per base step.
parallel_env = parallel_twin(guarded_env, "CartPoleParallel-v0", 0.02)
