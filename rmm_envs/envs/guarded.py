"""The blocking parallel-autonomy env skeleton: :class:`GuardedEnv`.

What every env with a built-in driver and a guardian action shares (``Dubins4DGuarded-v0``,
``Dubins3DMazeGuarded-v0``), on top of :class:`rmm_envs.envs.base.LabelledEnvBase`: ``step``
(the agent's compute time, the parsed guardian action, ``step_dt`` of the env's ``simulate``),
the driver's intended control ``info["nominal_control"]`` (applied exactly where the driver
controls), the per-step safety cost ``info["cost"]`` and the paper's Table I statistics
(``info["episode_stats"]``) with the episode's end.

``reset`` and ``simulate`` are written once, here, for every guarded env (the built-ins' and a
user's simulator's, :class:`rmm_envs.envs.any_env.GuardedAnyEnv`); a system supplies its parts
(:meth:`~GuardedEnv.begin`, :meth:`~GuardedEnv.begin_plant`, :meth:`~GuardedEnv.advance`
returning a :class:`Motion`, :meth:`~GuardedEnv.observe`, :meth:`~GuardedEnv.driver_control`,
:meth:`~GuardedEnv.final_speed`) and sets ``step_dt``, ``max_episode_sim_time``, ``clock`` and
``action_space``.  Each piece: :class:`GuardedEnv`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import cast

import gymnasium as gym
import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, parse
from rmm_envs.clocks import Clock
from rmm_envs.disturbances.hooks import Disturbable
from rmm_envs.envs.base import LabelledEnvBase
from rmm_envs.wrappers.nonblocking import BASE_STEP, TIME_ACCEL, NonBlockingStepping

__all__ = ["EPISODE_KEY", "REWARDS", "GuardedEnv", "Motion", "parallel_twin"]

#: The ``info`` key of the env's own episode statistics (Table I's), on the last step of an
#: episode.  Not ``"episode"``: Gymnasium's ``RecordEpisodeStatistics`` and SB3's ``Monitor``
#: write that key themselves (the first refuses to run when it is taken).
EPISODE_KEY = "episode_stats"

#: The reward of an interval by its outcome, where the system gives none of its own
REWARDS: dict[str | None, float] = {None: 0.0, "collision": -1.0, "goal": 1.0}


@dataclass(frozen=True)
class Motion:
    """What one interval did (:meth:`GuardedEnv.advance`): its ``outcome`` (``"collision"``,
    ``"goal"`` or ``None``), the ``control`` the plant received (after the actuators), the true
    ``state`` at its end (with it, ``info`` shows ``sim_time``, ``state``, ``active`` and
    ``control``; ``None`` where the env shows no state: a user's simulator), its ``reward``
    (``None``: :data:`REWARDS` of the outcome) and ``ended`` (the simulator ended the episode
    without an outcome)."""

    outcome: str | None
    control: np.ndarray
    state: np.ndarray | None = None
    reward: float | None = None
    ended: bool = False


class GuardedEnv(Disturbable, LabelledEnvBase):
    """The shared parallel-autonomy step (see the module docstring).

    * :meth:`step`: read the agent's compute time off ``self.clock``, parse the action with the
      action space (:class:`rmm_envs.autonomy.GuardianActionSpace`), advance by ``step_dt`` with
      the env's ``simulate(duration, active, control, compute_time)`` (which the non-blocking
      wrapper calls directly with its own durations), restart the clock.
    * The driver's intended control, ``info["nominal_control"]`` on ``reset`` and every step
      (:meth:`update_nominal`): computed from the state the returned observation shows, in the
      action space's control order and bounds, and kept, so that an interval the driver controls
      applies exactly these numbers.  A safety filter reads it as its ``u_nom``; a guardian
      returning ``action_space.active(info["nominal_control"])`` drives exactly as the driver does
      (tested bit for bit).
    * The per-step safety cost of Safety-Gymnasium's convention, ``info["cost"]``: 1.0 on a step
      that ends in a collision, 0.0 otherwise; its episode sum is ``cum_cost`` in the statistics.
    * The statistics of the paper's Table I (:meth:`episode_statistics`, ``info["episode_stats"]``:
      a key of its own, so that Gymnasium's ``RecordEpisodeStatistics`` and SB3's ``Monitor`` can
      write their ``info["episode"]``) and the end of a step: :meth:`end_interval` ends the episode
      on an outcome (``"goal"``, ``"collision"``) or at ``max_episode_sim_time`` (``"timeout"``,
      truncated) and adds ``outcome`` and ``episode_stats`` to the last step's ``info``.

    ``simulate`` applies ``self._nominal`` on an interval the driver controls, and calls
    :meth:`end_interval` after the state has advanced.

    Disturbances (:class:`rmm_envs.disturbances.hooks.Disturbable`): an env that takes them
    passes its ``disturbances`` argument to :meth:`set_disturbances`, calls
    :meth:`start_disturbances` at ``reset`` and routes its observation, applied control and
    state rates through :meth:`sensed`, :meth:`actuated` and :meth:`drift`."""

    step_dt: float
    max_episode_sim_time: float
    clock: Clock

    def step(self, action):
        compute = self.clock.elapsed()
        active, ctrl = parse(action, self.action_space)
        out = self.simulate(self.step_dt, active, ctrl, compute)
        self.clock.start()
        return out

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Seed the episode; the system's :meth:`begin` (world, start, driver); zero the
        statistics; draw the disturbances' episode and apply the plant's parameters
        (:meth:`begin_plant`); the driver's first control; then observe and start the agent's
        clock."""
        gym.Env.reset(self, seed=seed)
        start = self.begin(self.check_options(options))
        self.begin_statistics()
        self.begin_episode()
        self._last_active = False
        self._last_control = np.zeros(len(cast(GuardianActionSpace, self.action_space).control_low))
        self.start_disturbances(seed)
        self.begin_plant(self.plant_parameters())
        info: dict = {} if start is None else {"sim_time": 0.0, "state": np.array(start, dtype=float)}
        info["nominal_control"] = self.update_nominal()
        obs = self.observe()
        self.render_step()
        self.clock.start()
        return obs, info

    def begin(self, options: dict) -> np.ndarray | None:  # pragma: no cover - each system implements it
        """The system's part of ``reset``: draw (or take from ``options``, already checked) the
        episode's world and start, set ``self.scene``, reset the driver; return the true start
        state (``info["state"]``; ``None`` where the env shows none).  ``self.np_random`` is
        seeded."""
        raise NotImplementedError

    def begin_plant(self, parameters: dict[str, float] | None) -> None:
        """Apply the plant's parameters for this episode (a model mismatch drawn by the
        disturbances; ``None``: the nominal plant).  Default: nothing to apply."""

    def advance(self, duration: float, active: bool, control) -> Motion:  # pragma: no cover - each system
        """The system's physics over one interval of ``duration`` seconds: the driver's control
        ``self._nominal`` if not ``active``, else ``control`` (validated by the action space),
        through the actuators' disturbances; the plant moved to the interval's end or its first
        contact or arrival."""
        raise NotImplementedError

    def observe(self):  # pragma: no cover - each system implements it
        """The observation of the current state, through the sensors' disturbances."""
        raise NotImplementedError

    def render_step(self) -> None:
        """Show the frame after ``reset`` and each step in ``render_mode="human"``."""
        if self.render_mode == "human":
            self.render()

    def simulate(self, duration: float, active: bool, control, compute_time: float = 0.0):
        """Advance by ``duration`` seconds under one held control (``active``: the guardian's
        ``control``; else the driver's, chosen at the interval's start); ``compute_time`` is the
        agent's time charged to it (statistics only).  Used by :meth:`step` and the non-blocking
        wrapper; returns the usual 5-tuple."""
        self.check_interval(duration)
        moved = self.advance(duration, bool(active), control)
        self.count_interval(duration, active, compute_time)
        self._last_active = bool(active)
        self._last_control = moved.control
        reward = REWARDS[moved.outcome] if moved.reward is None else moved.reward
        info: dict = {}
        if moved.state is not None:  # an env that shows its state shows the interval too
            info.update(
                sim_time=self._sim_time, state=moved.state.copy(), active=bool(active), control=moved.control.copy()
            )
        terminated, truncated = self.end_interval(moved.outcome, reward, info, truncate=moved.ended)
        obs = self.observe()
        self.render_step()
        return obs, reward, terminated, truncated, info

    def begin_statistics(self) -> None:
        """Zero the simulated time and the episode's counters (call at ``reset``)."""
        self._sim_time = 0.0
        self._n_steps = 0
        self._n_active_steps = 0
        self._active_sim_time = 0.0
        self._cum_compute = 0.0
        self._cum_reward = 0.0
        self._cum_cost = 0.0

    def driver_control(self) -> np.ndarray:  # pragma: no cover - each env implements it
        """The driver's control at the current state.  Called once per observed state, whoever
        controls: a driver that keeps progress along a route (the maze's, the quadrotor's)
        follows the car there while the guardian drives, so handing its control back every
        step is the driver's episode exactly."""
        raise NotImplementedError

    def update_nominal(self) -> np.ndarray:
        """Compute and keep the driver's control at the current state (``self._nominal``, what an
        interval the driver controls applies); return a copy for ``info["nominal_control"]``.
        Call it once the state is the one the returned observation shows."""
        u = np.array(self.driver_control(), dtype=float).reshape(-1)
        space = cast(GuardianActionSpace, self.action_space)  # the contract's (a subclass sets it)
        np.minimum(np.maximum(u, space.control_low, out=u), space.control_high, out=u)
        self._nominal = u
        return u.copy()

    def check_interval(self, duration: float) -> None:
        """``RuntimeError`` before ``reset`` or after the end; ``ValueError`` for a bad duration."""
        self.check_can_step()
        if not (duration >= 0 and math.isfinite(duration)):
            raise ValueError(f"duration must be a finite number >= 0, got {duration}")

    def count_interval(self, duration: float, active: bool, compute_time: float) -> None:
        """Count one interval of ``duration`` simulated seconds (the guardian's if ``active``)."""
        self._n_steps += 1
        if active:
            self._n_active_steps += 1
            self._active_sim_time += duration
        self._cum_compute += compute_time
        self._sim_time += duration

    def end_interval(self, outcome: str | None, reward: float, info: dict, truncate: bool = False) -> tuple[bool, bool]:
        """``(terminated, truncated)`` after an interval with ``outcome`` (``None``: the episode
        goes on unless its time is up, or ``truncate`` says it ends without an outcome) and
        ``reward``; adds ``cost`` and ``nominal_control`` (the driver's control at the new state)
        to ``info`` and, on the last step, ends the episode and adds ``outcome`` and
        ``episode_stats``."""
        terminated = outcome is not None
        truncated = not terminated and (truncate or self._sim_time >= self.max_episode_sim_time - 1e-9)
        if truncated:
            outcome = "timeout"
        self._cum_reward += reward
        cost = 1.0 if outcome == "collision" else 0.0
        self._cum_cost += cost
        info["cost"] = cost
        info["nominal_control"] = self.update_nominal()
        if terminated or truncated:
            self.end_episode()
            info["outcome"] = outcome
            info[EPISODE_KEY] = self.episode_statistics(outcome)
        return terminated, truncated

    def final_speed(self) -> float:  # pragma: no cover - each env implements it
        raise NotImplementedError

    def episode_statistics(self, outcome: str | None = None) -> dict:
        n = self._n_steps
        return {
            "outcome": outcome,
            "n_env_steps": n,
            "n_active_ctrl_env_steps": self._n_active_steps,
            "active_ctrl_sim_time": self._active_sim_time,
            "cum_sim_time": self._sim_time,
            "cum_compute_time": self._cum_compute,
            "avg_compute_time": self._cum_compute / n if n else 0.0,
            "cum_reward": self._cum_reward,
            "cum_cost": self._cum_cost,
            "final_speed": self.final_speed(),
        }


def parallel_twin(blocking, env_id: str, base_step: float = BASE_STEP):
    """``env_id``'s entry point (a system's ``parallel_env``): the non-blocking twin of the env
    ``blocking`` makes (a blocking env's class, or a system's ``guarded_env``), as
    :func:`rmm_envs.envs.any_env.parallel` is the twin of :func:`~rmm_envs.envs.any_env.guarded`.
    The env is ``blocking(**kwargs)`` under :class:`rmm_envs.wrappers.NonBlockingStepping`
    (``time_accel``, ``base_step``, default ``base_step``; ``clock``).  ``step_dt``, the blocking
    env's fixed step, is refused by name: under non-blocking stepping each interval is
    ``elapsed * time_accel + base_step``, so a given ``step_dt`` would be silently ignored."""

    default_base_step = base_step

    def parallel_env(time_accel: float = TIME_ACCEL, base_step: float = default_base_step, clock=None, **kwargs):
        if "step_dt" in kwargs:
            raise ValueError(
                f"{env_id} steps by elapsed * time_accel + base_step, so step_dt (the fixed step of the "
                f"blocking env) does not apply; set base_step and time_accel instead, got "
                f"step_dt={kwargs['step_dt']!r}"
            )
        return NonBlockingStepping(blocking(**kwargs), time_accel=time_accel, base_step=base_step, clock=clock)

    parallel_env.__doc__ = (
        f"Entry point of ``{env_id}``: :obj:`{blocking.__name__}` under non-blocking "
        "stepping (see :func:`rmm_envs.envs.guarded.parallel_twin`)."
    )
    return parallel_env
