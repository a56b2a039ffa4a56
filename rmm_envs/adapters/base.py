"""Risk labels for a simulator the project did not write: the snapshot protocol, the scene built
on it and the labelling hooks an adapted env offers.

A simulator can be risk-labelled when it can save and restore its **full** state and step from
it: :class:`SnapshotSimulator` (``dt``, ``action_space``, ``get_state``, ``set_state``,
``step``, ``state_failed``).  :class:`SimulatorScene` turns one into a
:class:`rmm_envs.risk.RiskScene` (each branch holds one uniformly drawn control for the horizon
``t``, a whole number of env steps, and fails if any env step fails), so the estimator runs
unchanged; :class:`AdaptedEnv` offers the :class:`rmm_envs.risk.LabelledEnv` hooks for the env
it wraps, so :class:`rmm_envs.wrappers.RiskLabel` and ``rmm-datagen`` use it in place of a
package env.  :func:`rmm_envs.adapters.adapt` picks the adapter for an env.

What a label means here is :class:`SimulatorScene`'s docstring; why: docs/decisions/0009-simulator-adapters.md.
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable

import gymnasium as gym
import numpy as np

from rmm_envs.adapters.step_batch import batch_actions, batched_failed_ends, batched_paths
from rmm_envs.envs.base import rejection_sample

__all__ = ["AdaptedEnv", "SimulatorScene", "SnapshotScene", "SnapshotSimulator", "control_box", "env_actions"]


@runtime_checkable
class SnapshotSimulator(Protocol):
    """What the step-by-step scene (:class:`SnapshotScene`) needs of a simulator.

    ``dt``
        Seconds of simulated time per ``step``.
    ``action_space``
        A ``gymnasium.spaces.Box`` (controls are drawn uniformly in it) or ``Discrete(n)`` (served
        as the control box ``[start, start + n)``, a control ``u`` meaning action ``floor(u)``: each
        action is drawn with probability ``1/n``).
    ``get_state() -> (d,) float array``
        The full state: restoring it with ``set_state`` and stepping must give the same future as
        stepping on from where it was read.
    ``set_state(state)``
        Restore a state returned by ``get_state`` (or one a sampler made).
    ``step(action) -> bool``
        Advance ``dt`` seconds under ``action``; ``True`` when this step failed (for a Gymnasium
        env: its ``terminated``, where termination means failure).
    ``state_failed(states (N, d)) -> (N,) bool``
        Whether each state itself fails (checked at the root and after every step).
    """

    dt: float
    action_space: gym.Space

    def get_state(self) -> np.ndarray: ...

    def set_state(self, state: np.ndarray) -> None: ...

    def step(self, action) -> bool: ...

    def state_failed(self, states: np.ndarray) -> np.ndarray: ...


def control_box(space, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The control box the estimator samples for ``space`` (see :class:`SnapshotSimulator`);
    ``TypeError`` naming ``name`` and the space for any other kind of action space."""
    if isinstance(space, gym.spaces.Discrete):
        start = float(space.start)
        return np.array([start]), np.array([start + float(space.n)])
    if isinstance(space, gym.spaces.Box) and len(space.shape) == 1:
        lo, hi = np.asarray(space.low, float), np.asarray(space.high, float)
        if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)):
            return lo, hi
    raise TypeError(
        f"{name}: its action space {space} cannot be sampled uniformly; the risk adapters need "
        f"a bounded 1-D Box or a Discrete action space"
    )


def env_actions(space, controls, low, high) -> np.ndarray:
    """``(N, c)`` controls of the box :func:`control_box` gives -> ``(N, c)`` env actions:
    ``floor`` (clipped to the ``n`` actions, as int64) for ``Discrete``, the ``Box``'s dtype (the
    precision the env itself steps with) after clipping to ``[low, high]`` otherwise."""
    controls = np.asarray(controls, dtype=float)
    if isinstance(space, gym.spaces.Discrete):
        a = np.floor(controls[:, :1]) - space.start
        return np.clip(a, 0, space.n - 1).astype(np.int64) + space.start
    return np.clip(controls, low, high).astype(space.dtype).astype(float)


def _callable_name(fn) -> str:
    """``module:name`` of a function (as ``--failure`` names it), else its repr."""
    module, qualname = (
        getattr(fn, "__module__", None),
        getattr(fn, "__qualname__", None) or getattr(fn, "__name__", None),
    )
    return f"{module}:{qualname}" if module and qualname else repr(fn)


def _checked_failure(failure, name: str):
    if failure is not None and not callable(failure):
        raise TypeError(f"{name}: failure must be a callable failure(states (N, d)) -> (N,) bool, got {failure!r}")
    return failure


class SimulatorScene:
    """The :class:`rmm_envs.risk.RiskScene` of a simulator stepped every ``dt`` seconds.

    What "risk" means here: each branch holds one control, drawn uniformly from the action space,
    for the horizon ``t`` (a whole number of env steps: ``t / dt`` must be an integer up to 1e-9,
    else ``ValueError`` naming both); the env is stepped every ``dt`` and a branch **fails** if any
    env step fails (the step reports it, or the state after it fails by the adapter's failure
    test or the user's ``failure`` callable, or is not finite).  The path the scene returns holds
    ``n_steps`` of the ``t / dt + 1`` env-step states, equally spaced (rounded to env steps), and
    is ``NaN`` from the first failed env step on: failure is absorbing, so ``path_failed`` reads
    the path's last point.  A label is then the tree's risk metric over ``depth`` levels: the
    chance (expected value, CVaR or worst case) that random held controls reach a failure within
    ``depth * t`` seconds.  Failure: the adapter's own test (CartPole's termination, the MuJoCo
    envs' unhealthy states) and/or the user's vectorised ``failure(states (N, d)) -> (N,) bool``;
    where both exist a state fails if either says so.

    Subclasses implement :meth:`advance` (the env steps, batched where the simulator allows) and
    may implement :meth:`env_failed` (their env's own failure test of states).

    Args:
        name: the env's name, for error messages.
        state_dim: ``d``.  dt: seconds per env step.  action_space: the env's.
        failure: the user's ``failure(states) -> (N,) bool`` or ``None``.
        default_horizon: the horizon ``t`` (s) a label uses unless told otherwise.
    """

    def __init__(
        self, name: str, state_dim: int, dt: float, action_space, failure=None, default_horizon: float = 1.0
    ) -> None:
        self.name = name
        self.state_dim = int(state_dim)
        self.dt = float(dt)
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"{name}: the env's step length dt must be a finite number of seconds > 0, got {dt!r}")
        self.action_space = action_space
        self.control_low, self.control_high = control_box(action_space, name)
        self.failure = _checked_failure(failure, name)
        self.default_horizon = float(default_horizon)

    # -- what subclasses provide ------------------------------------------------------------
    def advance(self, states: np.ndarray, actions: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray | None]:
        """``(N, k, d)`` states after each of ``k`` env steps under the held ``actions``
        ``(N, a)`` (env format), and ``(N, k)`` step failures reported by the simulator (or
        ``None`` when only states fail)."""
        raise NotImplementedError

    def env_failed(self, states: np.ndarray) -> np.ndarray:
        """The env's own failure test of ``(N, d)`` states (none by default)."""
        return np.zeros(states.shape[0], dtype=bool)

    def advance_checked(self, states: np.ndarray, actions: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`advance`, and ``(N, k)`` whether each env step failed: the simulator said so or
        the state after it fails (:meth:`state_failed`).  Only the steps up to a branch's first
        failure matter (the path is cut there)."""
        after, step_failed = self.advance(states, actions, k)
        failed = self.state_failed(after.reshape(-1, self.state_dim)).reshape(-1, k)
        if step_failed is not None:
            failed |= step_failed
        return after, failed

    # -- controls ------------------------------------------------------------------------------
    def to_actions(self, controls: np.ndarray) -> np.ndarray:
        """Controls of the box -> env actions (:func:`env_actions`)."""
        return env_actions(self.action_space, controls, self.control_low, self.control_high)

    def env_steps(self, duration: float) -> int:
        """The whole number of env steps in ``duration`` seconds (``ValueError`` otherwise)."""
        k = round(float(duration) / self.dt)
        if k < 1 or abs(k * self.dt - duration) > 1e-9 * max(1.0, abs(duration)):
            raise ValueError(
                f"{self.name}: the horizon t = {duration!r} s must be a whole number >= 1 of the env's "
                f"steps of dt = {self.dt!r} s (for example {max(k, 1) * self.dt:g})"
            )
        return k

    # -- RiskScene -----------------------------------------------------------------------------
    def state_failed(self, states) -> np.ndarray:
        states = np.asarray(states, dtype=float)
        finite = np.isfinite(states)
        if finite.all():  # the usual case, without a reduction along rows (slow in numpy)
            return self._tests_failed(states)
        bad = ~np.all(finite, axis=1)
        out = bad.copy()
        ok = ~bad
        if ok.any():
            out[ok] = self._tests_failed(states[ok])
        return out

    def _tests_failed(self, good: np.ndarray) -> np.ndarray:
        """The env's failure test and the user's ``failure`` of finite states ``good``."""
        f = np.asarray(self.env_failed(good), dtype=bool)
        if self.failure is not None:
            user = np.asarray(self.failure(good))
            if user.shape != (good.shape[0],):
                raise ValueError(
                    f"{self.name}: failure(states) must return shape ({good.shape[0]},) for "
                    f"{good.shape[0]} states, got {user.shape} from failure = {_callable_name(self.failure)}"
                )
            f = f | user.astype(bool)
        return f

    def path_failed(self, paths) -> np.ndarray:
        return self.state_failed(np.asarray(paths)[:, -1])

    def propagate(self, states, controls, duration: float, n_steps: int) -> np.ndarray:
        states = np.asarray(states, dtype=float)
        k = self.env_steps(duration)
        traj = np.empty((states.shape[0], k + 1, self.state_dim))
        traj[:, 0] = states
        idx = np.round(np.linspace(0, k, int(n_steps))).astype(int)
        if not states.shape[0]:
            return traj[:, idx]
        after, failed = self.advance_checked(states, self.to_actions(controls), k)
        traj[:, 1:] = after
        path = traj[:, idx]  # only the points returned are cut at the first failure (NaN from there on)
        hit = np.flatnonzero(failed.any(axis=1))
        if hit.size:
            first = failed[hit].argmax(axis=1) + 1
            cut = path[hit]
            cut[idx[None, :] >= first[:, None]] = np.nan
            path[hit] = cut
        return path


class SnapshotScene(SimulatorScene):
    """The scene of any :class:`SnapshotSimulator`.  Step by step by default: every branch
    restores its start state and steps the simulator one env step at a time (the fallback, and
    the reference the batched paths are tested and timed against).

    **Batched.**  A simulator that also has ``step_batch(states (N, d), actions (N, a)) ->
    (states (N, d), failed (N,) bool)`` (every state advanced ``dt`` under its own action, arrays
    in, arrays out, without touching the simulator's own state) is stepped that way instead: all
    of a tree level's live branches at once, a branch leaving the batch at its first failed step,
    as the step-by-step path stops it.  Written with the same arithmetic as ``step``, it gives the
    same labels to the last bit (the tutorial's ``CartWall`` does: tests/test_snapshot_batch.py)
    at array speed (``python -m benchmarks.perf_snapshot_batch``).
    """

    def __init__(self, sim, name: str | None = None, failure=None, default_horizon: float = 1.0) -> None:
        name = name or type(sim).__name__
        missing = [
            m for m in ("dt", "action_space", "get_state", "set_state", "step", "state_failed") if not hasattr(sim, m)
        ]
        if missing:
            raise TypeError(f"{name} is not a SnapshotSimulator (see rmm_envs.adapters.base): it lacks {missing}")
        self.sim = sim
        super().__init__(name, np.asarray(sim.get_state()).shape[0], sim.dt, sim.action_space, failure, default_horizon)

    def env_failed(self, states):
        failed = np.asarray(self.sim.state_failed(states), dtype=bool)
        if failed.shape != (states.shape[0],):
            raise ValueError(
                f"{self.name}: state_failed on {states.shape[0]} states must return shape ({states.shape[0]},), "
                f"got {failed.shape}"
            )
        return failed

    def _env_action(self, a):
        if isinstance(self.action_space, gym.spaces.Discrete):
            return int(a[0])
        return a.astype(self.action_space.dtype)

    def advance(self, states, actions, k):
        if getattr(self.sim, "step_batch", None) is not None:
            out, step_failed, _ = batched_paths(self, states, actions, k, check=False)
            return out, step_failed
        out = np.full((states.shape[0], k, self.state_dim), np.nan)
        step_failed = np.zeros((states.shape[0], k), dtype=bool)
        saved = np.asarray(self.sim.get_state(), dtype=float).copy()
        try:
            for i in range(states.shape[0]):
                self.sim.set_state(states[i])
                action = self._env_action(actions[i])
                for j in range(k):
                    step_failed[i, j] = bool(self.sim.step(action))
                    out[i, j] = self.sim.get_state()
                    if step_failed[i, j]:
                        break
        finally:
            self.sim.set_state(saved)
        return out, step_failed

    def advance_checked(self, states, actions, k):
        if getattr(self.sim, "step_batch", None) is None:
            return super().advance_checked(states, actions, k)
        out, _, failed = batched_paths(self, states, actions, k, check=True)
        return out, failed

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``(failed (N,) bool, ends (N, d))`` of one tree level, the same bits as ``path_failed``
        of :meth:`propagate` and the paths' last points: through ``step_batch`` without a path
        array (:func:`rmm_envs.adapters.step_batch.batched_failed_ends`), else exactly that."""
        if getattr(self.sim, "step_batch", None) is None:
            paths = self.propagate(states, controls, duration, n_steps)
            return np.asarray(self.path_failed(paths), dtype=bool), paths[:, -1]
        k = self.env_steps(duration)
        if isinstance(self.action_space, gym.spaces.Discrete):
            return batched_failed_ends(self, states, batch_actions(self.action_space, self.to_actions(controls)), k)
        # to_actions without its round trip through float64 (the Box's dtype and back: the same values)
        acts = np.clip(np.asarray(controls, dtype=float), self.control_low, self.control_high)
        return batched_failed_ends(self, states, acts.astype(self.action_space.dtype), k)


class AdaptedEnv:
    """The :class:`rmm_envs.risk.LabelledEnv` hooks of an env the project did not write.

    Subclasses set ``self.scene`` (a :class:`SimulatorScene`) and implement ``true_state``,
    ``draw_states(rng, n)`` (candidate states for :meth:`sample_states`, which rejects the
    failed ones) and ``observe_states``.
    """

    #: the env ids this adapter is made for (documentation and ``adapt``'s error messages)
    env_ids: tuple[str, ...] = ()

    def __init__(self, env: gym.Env, scene: SimulatorScene) -> None:
        self.env = env
        self.unwrapped = env.unwrapped
        self.scene = scene

    @property
    def observation_space(self):
        return self.env.observation_space

    @property
    def action_space(self):
        return self.env.action_space

    @property
    def spec(self):
        return self.env.spec

    def reset(self, *, seed=None, options=None):
        return self.env.reset(seed=seed, options=options)

    def risk_scene(self) -> SimulatorScene:
        return self.scene

    @property
    def true_state(self) -> np.ndarray:
        raise NotImplementedError

    def draw_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        raise NotImplementedError

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` states that do not fail, drawn from ``rng`` only (see the adapter's sampler)."""
        return rejection_sample(
            rng,
            n,
            self.scene.state_dim,
            self.draw_states,
            self.scene.state_failed,
            f"non-failed states of {self.scene.name}",
        )

    def observe_states(self, states, rng=None) -> np.ndarray:
        raise NotImplementedError

    def privileged(self) -> dict:
        return {"state": self.true_state}

    def dataset_notes(self) -> dict:
        return {"obs_time_feature": None}
