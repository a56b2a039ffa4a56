"""Non-blocking stepping: the agent's thinking time passes in the simulated world.

The paper's ``step_to_now`` semantics (docs/original-code.md, item 19), on Gymnasium's ``step``:
``step(a)`` first advances the world by ``lap * time_accel + base_step`` simulated seconds,
where ``lap`` is the clock time elapsed since the previous ``step`` (or ``reset``) returned,
under the action set by the *previous* call; then it stores ``a`` for the next interval.  The
first interval after ``reset`` belongs to the built-in driver.  The clock is injectable
(:mod:`rmm_envs.clocks`): the real monotonic clock by default, a fixed-latency clock for
reproducible runs, the process CPU clock for runs that share cores.  A bad action raises
``ValueError`` *before* the world advances.  :meth:`NonBlockingStepping.episode_laps` gives the
episode's clock trace (every lap, in order), which :class:`rmm_envs.clocks.ReplayClock` replays.

What is charged as the agent's time, and how it differs from the original:
docs/decisions/0004-clocks.md.
"""

from __future__ import annotations

import math

import gymnasium as gym

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.clocks import Clock, make_clock

__all__ = ["BASE_STEP", "TIME_ACCEL", "NonBlockingStepping"]

#: The default simulated seconds per clock second (the paper's 10x) and simulated seconds added
#: to every step: the one place they are written (the ``Parallel`` envs' entry points and
#: ``rmm-bench --time-accel / --base-step`` read them from here).
TIME_ACCEL = 10.0
BASE_STEP = 0.1


class NonBlockingStepping(gym.Wrapper):
    """Wrap a parallel-autonomy env that offers ``simulate(duration, active, control, compute_time)``.

    The env's action space is a :class:`rmm_envs.autonomy.GuardianActionSpace`; actions are
    parsed by it.  The reset action is inactive, so an action takes effect one step late, as in the
    original.  The clock is restarted just before ``step`` returns, so only the agent's time
    between steps is charged, never the env's own physics and driver (the original started its
    stopwatch at the end of propagation, which leaked some post-processing into the lap).

    Args:
        env: the blocking environment (e.g. ``Dubins4DGuarded-v0``).
        time_accel: simulated seconds per clock second, ``>= 1`` as in the paper (default 10).
        base_step: simulated seconds added to every step, ``> 0`` (default 0.1).
        clock: a :class:`rmm_envs.clocks.Clock`, or ``"wall"``, ``"cpu"``, ``"fixed:MS"``.
    """

    def __init__(
        self,
        env: gym.Env,
        time_accel: float = TIME_ACCEL,
        base_step: float = BASE_STEP,
        clock: Clock | str | None = None,
    ):
        super().__init__(env)
        if not hasattr(env.unwrapped, "simulate"):
            raise TypeError(
                f"{type(env.unwrapped).__name__} has no simulate(duration, active, control, compute_time); "
                "NonBlockingStepping needs an env that can advance by an arbitrary duration"
            )
        if not (time_accel >= 1 and math.isfinite(time_accel)):
            raise ValueError(f"time_accel must be a finite number >= 1, got {time_accel!r}")
        if not (base_step > 0 and math.isfinite(base_step)):
            raise ValueError(f"base_step must be a finite number > 0, got {base_step!r}")
        self.time_accel = float(time_accel)
        self.base_step = float(base_step)
        self.clock = make_clock(clock)
        self._space = env.unwrapped.action_space
        if not isinstance(self._space, GuardianActionSpace):
            raise TypeError(
                f"{type(env.unwrapped).__name__}.action_space must be a GuardianActionSpace (the "
                f"parallel-autonomy contract, rmm_envs.autonomy), got {self._space!r}"
            )
        self._pending = self._space.parse(self._space.inactive())
        self._laps: list[float] = []

    def episode_laps(self) -> list[float]:
        """Every value the clock returned (``lap``, seconds) since the last ``reset``, in the order
        ``step`` read them: one per ``step`` call, a refused action's included.  A copy."""
        return list(self._laps)

    def reset(self, *, seed=None, options=None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._pending = self._space.parse(self._space.inactive())
        self._laps = []
        self.clock.start()
        return obs, info

    def step(self, action):
        lap = self.clock.elapsed()
        self._laps.append(lap)
        parsed = self._space.parse(action)
        active, control = self._pending
        out = self.env.unwrapped.simulate(lap * self.time_accel + self.base_step, active, control, lap)
        self._pending = parsed
        self.clock.start()
        return out
