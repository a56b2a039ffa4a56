"""Simulators of your own: the hooks such a simulator may or must have (:data:`SIMULATOR_HOOKS`,
printed as the tutorial's table by :func:`hooks_table`), :class:`SnapshotEnv` (a simulator as a
Gymnasium env) and :class:`SnapshotAdapter` (its labelling hooks).

An object handed to :func:`rmm_envs.envs.any_env.guarded` that is not a Gymnasium env is such a
simulator: the snapshot protocol (:class:`rmm_envs.adapters.SnapshotSimulator`) and the optional
hooks of the table.  A hook missing for what is asked is a ``TypeError`` that names the
simulator, the hook and the command that needs it, with the sentence of the table that says what
it is for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from rmm_envs.adapters.base import AdaptedEnv, SnapshotScene

__all__ = [
    "SIMULATOR_HOOKS",
    "SimulatorHook",
    "SnapshotAdapter",
    "SnapshotEnv",
    "can_render",
    "hooks_table",
    "is_simulator",
    "require_hooks",
]

#: the commands a hook can be needed by (the ``needed_by`` of :class:`SimulatorHook`)
GUARDED = "guarded()/parallel() (every env they make: rmm-bench, rmm-datagen)"
DATAGEN = "rmm-datagen"
LABELS = "rmm-datagen and every risk label (risk_scene())"
RENDER = "render_mode='rgb_array' or 'human'"


@dataclass(frozen=True)
class SimulatorHook:
    """One member a simulator of your own may or must have (see :data:`SIMULATOR_HOOKS`)."""

    name: str
    signature: str
    called: str
    default: str | None  # None: required by ``needed_by``
    needed_by: str
    purpose: str

    def missing(self, sim_name: str, command: str | None = None) -> str:
        """The one-line message for a simulator that lacks this hook."""
        return (
            f"{sim_name} lacks the hook {self.signature}, which {command or self.needed_by} needs: {self.purpose} "
            f"(every hook: rmm_envs.envs.any_env.SIMULATOR_HOOKS, docs/tutorials/own-simulator.md)"
        )


#: Every member a simulator of your own (an object handed to :func:`guarded` / :func:`parallel`
#: that is not a Gymnasium env) may or must have, in the order the tutorial lists them.  The first
#: six are the snapshot protocol (:class:`rmm_envs.adapters.SnapshotSimulator`).
SIMULATOR_HOOKS: dict[str, SimulatorHook] = {
    h.name: h
    for h in (
        SimulatorHook(
            "dt",
            "dt (float, seconds)",
            "once, when the env is made",
            "`step_dt`, if guarded() is given one",
            GUARDED,
            "the simulated seconds one step advances",
        ),
        SimulatorHook(
            "action_space",
            "action_space (a bounded 1-D gymnasium Box, or Discrete)",
            "once, when the env is made",
            None,
            GUARDED,
            "the actions the driver, the safe default and the guardians apply, and the box a risk label's "
            "random controls are drawn from",
        ),
        SimulatorHook(
            "get_state",
            "get_state() -> (d,) float array",
            "when the env is made, after every step, before and after every risk label",
            None,
            GUARDED,
            "the full state: set_state of it and stepping on must give the same future",
        ),
        SimulatorHook(
            "set_state",
            "set_state(state)",
            "at every reset, and before every branch of a risk label",
            None,
            GUARDED,
            "restore a state that get_state returned or sample_states drew",
        ),
        SimulatorHook(
            "step",
            "step(action) -> bool",
            "every simulated step of an episode and of every branch of a risk label",
            None,
            GUARDED,
            "advance dt seconds under the action and return True when this step failed (the episode ends as a "
            "collision)",
        ),
        SimulatorHook(
            "state_failed",
            "state_failed(states (N, d)) -> (N,) bool",
            "at a risk label's root and after each of its steps; on every sampled state",
            None,
            LABELS,
            "which states fail in themselves (labelled 1, never sampled)",
        ),
        SimulatorHook(
            "step_batch",
            "step_batch(states (N, d), actions (N, a)) -> (states (N, d), failed (N,) bool)",
            "by every risk label, once per env step of a tree level, on all of its live branches",
            "`set_state` and `step`, one branch at a time",
            LABELS,
            "step many states at once, arrays in, arrays out, leaving the simulator's own state alone: labels at "
            "array speed (100x on a simulator with rays); written with step's arithmetic it gives the same labels "
            "to the last bit",
        ),
        SimulatorHook(
            "initial_state",
            "initial_state(rng) -> (d,) float array",
            "at every reset, with a generator drawn from the reset seed",
            "the state the simulator held when `guarded()` got it",
            GUARDED,
            "where an episode starts",
        ),
        SimulatorHook(
            "observe",
            "observe(state) -> observation array",
            "after every reset and step, and on every state a dataset labels",
            "the state itself, as `float32`",
            GUARDED,
            "what the driver, the safe default, the success test and the guardians read (a risk model's input)",
        ),
        SimulatorHook(
            "observation_space",
            "observation_space (a gymnasium Box)",
            "once, when the env is made",
            "`Box(-inf, inf)` of the shape `observe` returns, `float32`",
            GUARDED,
            "the env's observation space",
        ),
        SimulatorHook(
            "sample_states",
            "sample_states(rng, n) -> (n, d) float array",
            "by rmm-datagen, once per configuration (failed states are drawn again)",
            None,
            DATAGEN,
            "half of the states a dataset labels (the other half: states the driver visits); draw from rng only, "
            "and cover the states a guardian will meet",
        ),
        SimulatorHook(
            "default_horizon",
            "default_horizon (float, seconds, a whole number of steps)",
            "by rmm-datagen without --horizon, and RiskLabel without horizon=",
            "10 steps (`10 * dt`)",
            DATAGEN,
            "how long each random control of a risk label's tree is held",
        ),
        SimulatorHook(
            "privileged",
            "privileged() -> dict",
            "by guardians that read privileged information, and for analysis",
            '`{"state": get_state()}`',
            DATAGEN,
            "the information the observation hides",
        ),
        SimulatorHook(
            "dataset_notes",
            "dataset_notes() -> dict",
            "by rmm-datagen, once, into the dataset's metadata",
            '`{"obs_time_feature": None}`',
            DATAGEN,
            "facts about observe a dataset records (obs_time_feature: how a time feature is drawn, or None)",
        ),
        SimulatorHook(
            "start_doomed",
            "start_doomed(state) -> bool",
            "by rmm-bench, once per episode right after reset",
            "not assessed (the doomed-start columns say so)",
            GUARDED,
            "whether no control the simulator allows can avoid a failure from this start (doomed), so Table I "
            "tells avoidable collisions apart; it must not change the simulator's state",
        ),
        SimulatorHook(
            "render",
            "render(state) -> (H, W, 3) uint8 array",
            "at every env.render()",
            None,
            RENDER,
            "the picture of a state (render_mode='human' shows it with pygame)",
        ),
    )
}


def hooks_table() -> str:
    """:data:`SIMULATOR_HOOKS` as the Markdown table of the tutorial."""
    rows = ["| hook | signature | when it is called | default |", "|---|---|---|---|"]
    for h in SIMULATOR_HOOKS.values():
        default = f"required by {h.needed_by}" if h.default is None else h.default
        rows.append(f"| `{h.name}` | `{h.signature}` | {h.called} | {default} |")
    return "\n".join(rows)


def is_simulator(env) -> bool:
    return not isinstance(env, (str, gym.Env))


def require_hooks(sim, names, command: str | None = None, sim_name: str | None = None) -> None:
    """``TypeError`` (one line: the simulator, the hook, ``command`` and what the hook is for) for
    the first of ``names`` that ``sim`` lacks."""
    for name in names:
        if getattr(sim, name, None) is None:
            raise TypeError(SIMULATOR_HOOKS[name].missing(sim_name or type(sim).__name__, command))


def can_render(sim) -> bool:
    """Whether the simulator ``sim`` has the hook ``render(state)``."""
    return getattr(sim, "render", None) is not None  # as require_hooks sees a hook


def _float_state(state, what: str, name: str) -> np.ndarray:
    s = np.array(state, dtype=float)
    if s.ndim != 1 or s.size == 0:
        raise ValueError(f"{name}: {what} must be a (d,) float array, got shape {s.shape}")
    return s


class SnapshotEnv(gym.Env):
    """A simulator of your own as a Gymnasium env (see *Simulators of your own* in the module
    docstring and :data:`SIMULATOR_HOOKS`): reward 0, ``terminated`` when its ``step`` fails,
    never truncated (:class:`GuardedAnyEnv` ends episodes by time)."""

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"]}

    def __init__(self, sim, name: str | None = None, dt: float | None = None, render_mode: str | None = None) -> None:
        self.sim = sim
        self.name = name or type(sim).__name__
        require_hooks(sim, ("action_space", "get_state", "set_state", "step"), sim_name=self.name)
        own = getattr(sim, "dt", None)
        if own is None and dt is None:
            raise TypeError(SIMULATOR_HOOKS["dt"].missing(self.name, GUARDED + " without step_dt"))
        value: Any = own if own is not None else dt
        try:
            self.dt = float(value)
        except (TypeError, ValueError):
            self.dt = math.nan
        if not (math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"{self.name}: dt must be a finite number of seconds > 0, got {own!r}")
        if render_mode is not None:
            require_hooks(sim, ("render",), f"render_mode={render_mode!r}", self.name)
        self.render_mode = render_mode
        # what this env can render: both modes with the simulator's render hook, none without it
        self.metadata = {"render_modes": list(self.metadata["render_modes"]) if can_render(sim) else []}
        self.action_space = sim.action_space
        self._start = _float_state(sim.get_state(), "get_state()", self.name)
        self.observation_space = getattr(sim, "observation_space", None) or gym.spaces.Box(
            -np.inf, np.inf, self.observe(self._start).shape, np.float32
        )

    def observe(self, state) -> np.ndarray:
        fn = getattr(self.sim, "observe", None)
        return np.asarray(state, dtype=np.float32) if fn is None else np.asarray(fn(state))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        init = getattr(self.sim, "initial_state", None)
        start = self._start if init is None else _float_state(init(self.np_random), "initial_state(rng)", self.name)
        self.sim.set_state(start.copy())
        return self.observe(self.sim.get_state()), {}

    def step(self, action):
        failed = bool(self.sim.step(action))
        return self.observe(self.sim.get_state()), 0.0, failed, False, {}

    def render(self):
        if self.render_mode is None:
            return None
        return np.asarray(self.sim.render(self.sim.get_state()))


class _WithStep:
    """A simulator seen with a ``dt`` of its own (``step_dt``) for :class:`SnapshotScene`."""

    def __init__(self, sim, dt: float) -> None:
        self._sim, self.dt = sim, dt

    def __getattr__(self, name):
        return getattr(self._sim, name)


class SnapshotAdapter(AdaptedEnv):
    """The :class:`rmm_envs.risk.LabelledEnv` hooks of a :class:`SnapshotEnv`: the simulator's
    :class:`SnapshotScene`, its ``sample_states`` as the sampler's draws, ``observe`` on each state."""

    def __init__(self, env: SnapshotEnv, command: str | None = None) -> None:
        sim = env.sim
        require_hooks(sim, ("state_failed",), command, env.name)
        view = sim if getattr(sim, "dt", None) is not None else _WithStep(sim, env.dt)
        horizon = getattr(sim, "default_horizon", None)
        super().__init__(
            env, SnapshotScene(view, name=env.name, default_horizon=10 * env.dt if horizon is None else horizon)
        )
        self.snapshot_env, self.command = env, command

    @property
    def true_state(self) -> np.ndarray:
        return np.array(self.snapshot_env.sim.get_state(), dtype=float)

    def draw_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        sim = self.snapshot_env.sim
        require_hooks(sim, ("sample_states",), self.command, self.snapshot_env.name)
        states = np.asarray(sim.sample_states(rng, n), dtype=float)
        if states.shape != (n, self.scene.state_dim):
            raise ValueError(
                f"{self.snapshot_env.name}: sample_states(rng, {n}) must return shape ({n}, {self.scene.state_dim}), "
                f"got {states.shape}"
            )
        return states

    def observe_states(self, states, rng=None) -> np.ndarray:
        obs = [self.snapshot_env.observe(s) for s in np.asarray(states, dtype=float)]
        shape = tuple(self.snapshot_env.observation_space.shape or ())
        return np.array(obs, dtype=np.float32).reshape((len(obs), *shape))

    def privileged(self) -> dict:
        fn = getattr(self.snapshot_env.sim, "privileged", None)
        return {"state": self.true_state} if fn is None else fn()

    def dataset_notes(self) -> dict:
        fn = getattr(self.snapshot_env.sim, "dataset_notes", None)
        return {"obs_time_feature": None} if fn is None else fn()
