"""Two guarded envs built with :func:`rmm_envs.envs.driven.guarded` around simulators the project
did not write: ``CartPoleGuarded-v0`` (Gymnasium's ``CartPole-v1``) and
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
which registers their entry points below.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "TargetTask",
    "cartpole_guarded",
    "cartpole_parallel",
    "inverted_pendulum_guarded",
    "inverted_pendulum_parallel",
]

#: CartPole's balancing gains: ``u = -K s`` of the continuous-time LQR (see the module docstring)
CARTPOLE_K = (-3.16227766, -5.91549435, -49.50716842, -12.84439629)
#: InvertedPendulum's balancing gains (state ``(x, theta, x_dot, theta_dot)``; see the module docstring)
PENDULUM_K = (-0.72237285, -6.830044, -0.92326489, -1.08445913)


@dataclass
class TargetTask:
    """The driver and success test of one example (see the module docstring).

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


def _task(env_id: str) -> tuple[TargetTask, dict]:
    if env_id == "CartPole-v1":
        return TargetTask(
            CARTPOLE_K, pos=0, ang=2, dt=0.02, near=0.6, far=1.8, g_lo=1.0, g_hi=4.0, tol_x=0.2, hold=1.0, discrete=True
        ), {"controls": ("force_ctrl",), "max_episode_sim_time": 10.0}
    return TargetTask(
        PENDULUM_K, pos=0, ang=1, dt=0.04, near=0.3, far=0.8, g_lo=1.0, g_hi=4.0, tol_x=0.1, hold=1.0, discrete=False
    ), {"controls": ("force_ctrl",), "max_episode_sim_time": 10.0}


def _guarded(env_id: str, clock=None, **kwargs):
    from rmm_envs.envs.driven import guarded

    task, defaults = _task(env_id)
    return guarded(
        env_id, driver=task, safe_default=task.balance, success=task.reached, clock=clock, **(defaults | kwargs)
    )


def cartpole_guarded(clock=None, **kwargs):
    """Entry point of ``CartPoleGuarded-v0`` (keywords as :func:`rmm_envs.envs.driven.guarded`)."""
    return _guarded("CartPole-v1", clock=clock, **kwargs)


def inverted_pendulum_guarded(clock=None, **kwargs):
    """Entry point of ``InvertedPendulumGuarded-v0`` (keywords as :func:`rmm_envs.envs.driven.guarded`)."""
    return _guarded("InvertedPendulum-v5", clock=clock, **kwargs)


def _parallel(entry, env_id: str, base_step: float):
    from rmm_envs.envs.guarded import parallel_entry_point

    return parallel_entry_point(entry, env_id, base_step=base_step)


#: Entry point of ``CartPoleParallel-v0``: ``CartPoleGuarded-v0`` stepped non-blocking, one env step (0.02 s) per base step.
cartpole_parallel = _parallel(cartpole_guarded, "CartPoleParallel-v0", 0.02)
#: Entry point of ``InvertedPendulumParallel-v0``: one env step (0.04 s) per base step.
inverted_pendulum_parallel = _parallel(inverted_pendulum_guarded, "InvertedPendulumParallel-v0", 0.04)
