"""Parallel autonomy around any Gymnasium env: :func:`guarded` and :class:`DrivenGuardedEnv`.

Give an env (a Gymnasium env, or a simulator of your own written against the snapshot protocol,
see *Simulators of your own* below), a **driver** that controls it by default, a **safe default**
and a **success** test, and get an env with the contract of :mod:`rmm_envs.autonomy` (the one every guardian and
``rmm-bench`` speak), built on the same skeleton as the package's own guarded envs
(:class:`rmm_envs.envs.guarded.GuardedEnv`)::

    from rmm_envs.envs.driven import guarded
    env = guarded("CartPole-v1", driver=my_policy, safe_default=balance, success=at_target)

Arguments (each refused by name, with what was expected, when it does not fit):

``env``
    A Gymnasium env or its id (``gym.make``'d, with ``render_mode``), or a simulator of your own
    (any object that is not a ``gymnasium.Env``; see below).  Its action space is
    ``Discrete(n)`` or a bounded 1-D ``Box``; its observation is what the guardian reads,
    unchanged.
``driver``
    ``driver(obs) -> action`` in the env's action space, or an SB3-style policy (an object with
    ``predict(obs, deterministic=True) -> (action, state)``).  An action outside the space is a
    ``ValueError`` naming the driver, the action and the space.
``safe_default``
    ``safe_default(obs) -> action`` or one constant action: what ``brakes`` applies (and
    ``lrmm`` with ``action="safe"``): the env's :class:`rmm_envs.autonomy.SafeDefault`.
``success``
    ``success(obs) -> bool``, asked after every env step: the episode ends as ``"goal"``.
``failure``
    ``None`` (default): the env's own termination, for envs whose termination means failure
    (:func:`rmm_envs.adapters.termination_is_failure`: CartPole, the MuJoCo envs with an
    unhealthy state) and simulators of your own (their ``step`` returns ``True``); any other env
    is refused unless told: ``"terminated"`` (its termination is failure) or
    ``failure(obs) -> bool``.  A failed step ends the episode as ``"collision"``, with
    ``info["cost"] = 1.0``.
``controls``
    The guardian action's control fields (default ``("u0", "u1", ...)``, one per action
    component; one for ``Discrete``).
``step_dt``, ``max_episode_sim_time``
    Seconds per blocking step (default: the env's own step) and per episode (default: the
    env's ``max_episode_steps`` times its step).  The env's own step is its ``dt`` (``tau`` for
    CartPole); an env or simulator without one takes ``step_dt`` as its step, so one of the two
    is needed.  :func:`parallel` steps ``step_dt`` per base step when it is given.
``render_mode``
    ``None``, ``"rgb_array"`` (the env's frame) or ``"human"`` (the env's own window where it
    has one, else its ``rgb_array`` frame shown with pygame).

Per episode, each of ``driver``, ``safe_default`` and ``success`` with a method
``begin_episode(rng)`` has it called at ``reset`` with a generator drawn from the reset seed
(a driver's random target, a success test's hold counter start there).

**Controls.**  The guardian's control box is the env's: the ``Box`` bounds, or
``[start, start + n]`` for ``Discrete(n)``, a control ``u`` meaning action ``floor(u)`` (the
risk adapters' convention, :func:`rmm_envs.adapters.base.control_box`).  The driver's action
``a`` appears in ``info["nominal_control"]`` as that control (``float(a)`` for ``Discrete``), so
handing it back applies exactly the driver's action.

**Stepping.**  ``step`` advances ``step_dt``; the non-blocking twin (:func:`parallel`,
:class:`rmm_envs.wrappers.NonBlockingStepping`) advances by the guardian's compute time as the
package's other parallel envs do.  An interval of ``d`` seconds makes the env steps whose end
falls within the simulated time so far (the remainder carries over, so a short interval may
make none), all under one control: the guardian's if it is active, else the driver's action at
the observed state.  After each env step: failure -> ``"collision"``, else success ->
``"goal"``, else the env's truncation (or a termination that is not a failure) -> ``"timeout"``;
``max_episode_sim_time`` -> ``"timeout"``.  ``info["episode_stats"]`` holds Table I's statistics
(without the optional ``final_speed``: there is no vehicle).

**Labels.**  Where a risk adapter serves the env (:mod:`rmm_envs.adapters`), the guarded env
offers the :class:`rmm_envs.risk.LabelledEnv` hooks, so ``rmm-datagen --env <guarded id>`` labels
it: the adapter's scene (its failure test; its default horizon is the one ``rmm-datagen`` uses
without ``--horizon``), state and observation, and a state sampler that draws half of each
batch from the adapter's own sampler and half from the states the driver alone visits (seeded
episodes of a second copy of the env, failed states left out), so a model sees the states the
guardian will meet.

**Simulators of your own.**  An object that is not a Gymnasium env is a simulator written
against the snapshot protocol (:class:`rmm_envs.adapters.SnapshotSimulator`) and, optionally,
a few more hooks: the table :data:`SIMULATOR_HOOKS` (name, signature, when it is called,
default; the tutorial ``docs/tutorials/own-simulator.md`` prints it).  Nothing of this package
needs to be inside it.  :class:`SnapshotEnv` makes it a Gymnasium env (an episode starts at
``initial_state(rng)``, ``step`` ends it as failed when the simulator's ``step`` returns
``True``, the observation is ``observe(state)``) and its labels come from
:class:`rmm_envs.adapters.SnapshotScene` (one branch at a time through ``set_state`` and
``step``).  A hook missing for what is asked is a ``TypeError`` that names the simulator, the
hook and the command that needs it, with the sentence of the table that says what it is for.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from rmm_envs.adapters.base import AdaptedEnv, SnapshotScene
from rmm_envs.autonomy import GENERIC, GuardianActionSpace, SafeDefault
from rmm_envs.envs.guarded import GuardedEnv
from rmm_envs.starts import StartAssessment
from rmm_envs.wrappers.nonblocking import TIME_ACCEL, NonBlockingStepping

__all__ = [
    "SIMULATOR_HOOKS",
    "DrivenGuardedEnv",
    "GivenSafeDefault",
    "SimulatorHook",
    "SnapshotEnv",
    "guarded",
    "hooks_table",
    "parallel",
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
            f"(every hook: rmm_envs.envs.driven.SIMULATOR_HOOKS, docs/tutorials/own-simulator.md)"
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


def _is_simulator(env) -> bool:
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
    never truncated (:class:`DrivenGuardedEnv` ends episodes by time)."""

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


#: ``self.scene`` while an episode runs (``None`` before the first ``reset``, as for every env of
#: the package); :meth:`DrivenGuardedEnv.risk_scene` gives the risk adapter's scene instead
_RUNNING = "running"


def _name(obj) -> str:
    return getattr(obj, "__qualname__", None) or type(obj).__name__


class _Actions:
    """Conversions between the env's actions and the guardian's control vectors."""

    def __init__(self, space, env_name: str) -> None:
        from rmm_envs.adapters.base import control_box

        self.space = space
        self.discrete = isinstance(space, gym.spaces.Discrete)
        self.low, self.high = control_box(space, env_name)

    def check(self, action, who: str):
        """``action`` as the env takes it; ``ValueError`` naming ``who`` when it is outside the space."""
        arr = np.asarray(action)
        if self.discrete:
            ok = arr.size == 1 and arr.dtype.kind in "iu" and self.space.contains(int(arr.reshape(-1)[0]))
            if ok:
                return int(arr.reshape(-1)[0])
        else:
            ok = (
                arr.dtype.kind in "fiu"
                and arr.size == self.space.shape[0]
                and bool(np.all(np.isfinite(arr)))
                and bool(np.all((arr.reshape(-1) >= self.space.low) & (arr.reshape(-1) <= self.space.high)))
            )
            if ok:
                return arr.reshape(self.space.shape).astype(self.space.dtype)
        raise ValueError(f"{who} returned the action {action!r}, outside the env's action space {self.space}")

    def control(self, action) -> np.ndarray:
        """The control vector of a checked env action."""
        return np.asarray(action, dtype=float).reshape(-1)

    def action(self, control):
        """The env action of a control vector of the box."""
        from rmm_envs.adapters.base import env_actions

        a = env_actions(self.space, np.asarray(control, dtype=float).reshape(1, -1), self.low, self.high)[0]
        return int(a[0]) if self.discrete else a.astype(self.space.dtype)


def _policy(obj, what: str):
    """``obj`` as a function ``obs -> action``: a callable, or an SB3-style ``predict``."""
    predict = getattr(obj, "predict", None)
    if callable(predict) and not callable(obj):
        return lambda obs: predict(obs, deterministic=True)[0]
    if callable(obj):
        return obj
    raise TypeError(
        f"{what} must be a callable obs -> action or an object with predict(obs, deterministic=True) "
        f"(an SB3-style policy), got {obj!r}"
    )


class GivenSafeDefault(SafeDefault):
    """The safe default handed to :func:`guarded`: a policy ``obs -> action`` or one constant action."""

    def __init__(self, fn, actions: _Actions, constant=None) -> None:
        self._fn, self._actions, self._constant = fn, actions, constant
        self.description = f"the constant action {constant!r}" if fn is None else f"the policy {_name(fn)}"

    def policy(self, space, rng, **options):
        self.check_options(options)
        if self._fn is None:
            u = self._actions.control(self._constant)
            return lambda obs: u.copy()
        fn, acts = self._fn, self._actions
        return lambda obs: acts.control(acts.check(fn(obs), f"the safe default {_name(fn)}"))


class DrivenGuardedEnv(GuardedEnv):
    """An env with a driver, a safe default and a success test; see the module docstring."""

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"]}
    render_mode: str | None = None

    def __init__(
        self,
        env,
        driver,
        safe_default,
        success,
        failure=None,
        controls=None,
        step_dt: float | None = None,
        max_episode_sim_time: float | None = None,
        clock=None,
        render_mode: str | None = None,
    ) -> None:
        from rmm_envs.adapters import termination_is_failure
        from rmm_envs.clocks import make_clock

        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        if step_dt is not None:
            try:
                ok = not isinstance(step_dt, bool) and math.isfinite(float(step_dt)) and float(step_dt) > 0
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"step_dt must be a finite number of seconds > 0, got {step_dt!r}")
        self.simulator = env if _is_simulator(env) else None
        self._own_window = False  # human: the base env shows itself, or this env shows its rgb_array frames
        self.env: gym.Env
        if self.simulator is not None:
            self.env = SnapshotEnv(
                env, dt=step_dt, render_mode=None if render_mode is None else "rgb_array"
            )  # TypeError naming a missing hook
            self._own_window = render_mode == "human"
        elif isinstance(env, str):
            self.env = self._make(env, render_mode)
        else:
            self.env = env
            if render_mode is not None and getattr(env, "render_mode", None) != render_mode:
                raise ValueError(
                    f"render_mode={render_mode!r} needs an env made with it; got an env with render_mode="
                    f"{getattr(env, 'render_mode', None)!r} (pass its id, or make it with render_mode={render_mode!r})"
                )
        self.render_mode = render_mode
        spec = getattr(self.env, "spec", None)
        self.env_name = (
            self.env.name
            if isinstance(self.env, SnapshotEnv)
            else spec.id
            if spec is not None and spec.id
            else type(self.env.unwrapped).__name__
        )
        self._acts = _Actions(self.env.action_space, self.env_name)
        self._driver = _policy(driver, "driver")
        self._driver_obj = driver
        if not callable(success):
            raise TypeError(f"success must be a callable success(obs) -> bool, got {success!r}")
        self._success = success
        if self.simulator is not None and failure is not None:
            raise ValueError(
                f"failure: the simulator {self.env_name} reports its failures itself (its step returns True), "
                f"so guarded() takes no failure for it; got {failure!r}"
            )
        if failure is None and self.simulator is None and not termination_is_failure(self.env):
            raise ValueError(
                f"{self.env_name} has no known failure notion (its termination means failure only for "
                "CartPole and the MuJoCo envs with an unhealthy state); give failure='terminated' if its "
                "termination is a failure, or failure=callable(obs) -> bool"
            )
        if not (failure is None or failure == "terminated" or callable(failure)):
            raise TypeError(f"failure must be None, 'terminated' or a callable failure(obs) -> bool, got {failure!r}")
        self._failure = None if failure in (None, "terminated") else failure
        self._safe_obj = safe_default
        if callable(safe_default) or callable(getattr(safe_default, "predict", None)):
            safe = GivenSafeDefault(_policy(safe_default, "safe_default"), self._acts)
        else:
            try:
                constant = self._acts.check(safe_default, "safe_default")
            except ValueError:
                raise TypeError(
                    f"safe_default must be a callable obs -> action, an SB3-style policy or a constant "
                    f"action in the env's action space {self.env.action_space}, got {safe_default!r}"
                ) from None
            safe = GivenSafeDefault(None, self._acts, constant)
        k = len(self._acts.low)
        names = (
            tuple(f"u{i}" for i in range(k))
            if controls is None
            else ()
            if isinstance(controls, str)
            else tuple(controls)
        )
        if len(names) != k:  # a string would be one name per letter
            hint = f" (a string; one name is {(controls,)!r})" if isinstance(controls, str) else ""
            raise ValueError(
                f"controls must name each control of {self.env_name}'s action space {self.env.action_space} "
                f"({k} control{'s' if k > 1 else ''}), got {controls!r}{hint}"
            )
        self.action_space = GuardianActionSpace(names, self._acts.low, self._acts.high, safe_default=safe, kind=GENERIC)
        self.observation_space = self.env.observation_space
        self.dt = self._env_dt(step_dt)
        self.step_dt = self.dt if step_dt is None else float(step_dt)
        steps = getattr(spec, "max_episode_steps", None)
        if max_episode_sim_time is None:
            if steps is None:
                raise ValueError(f"{self.env_name} has no max_episode_steps; give max_episode_sim_time (seconds)")
            max_episode_sim_time = steps * self.dt
        self.max_episode_sim_time = float(max_episode_sim_time)
        if not (math.isfinite(self.max_episode_sim_time) and self.max_episode_sim_time > 0):
            raise ValueError(
                f"max_episode_sim_time must be a finite number of seconds > 0, got {self.max_episode_sim_time!r}"
            )
        self.metadata = {"render_modes": self._render_modes()}  # what it can render, as check_env reads it
        if render_mode is not None:
            self.metadata["render_fps"] = max(round(1.0 / self.step_dt), 1)
        self.clock = make_clock(clock)
        if self.simulator is not None and getattr(self.simulator, "start_doomed", None) is not None:
            self.doomed_test = self._start_doomed  # rmm_envs.starts finds it on the env
        self._adapter: AdaptedEnv | None = None
        self._sampler: tuple[gym.Env, AdaptedEnv] | None = None

    def _start_doomed(self, env) -> StartAssessment:
        """The simulator's own doomed-start test of the state it starts from."""
        sim = self.simulator
        saved = np.array(sim.get_state(), dtype=float)
        try:
            doomed = sim.start_doomed(saved.copy())
        finally:
            sim.set_state(saved)
        if not isinstance(doomed, bool | np.bool_):
            raise TypeError(f"{self.env_name}: start_doomed(state) must return a bool, got {doomed!r}")
        return StartAssessment(bool(doomed), f"{type(sim).__name__}.start_doomed")

    # ------------------------------------------------------------------ the env
    def _make(self, env_id: str, render_mode: str | None) -> gym.Env:
        """``gym.make(env_id)`` with the render mode the env can serve (``"human"``: its own
        window if it has one, else its ``rgb_array`` frames shown by this env)."""
        if render_mode is None:
            return gym.make(env_id)
        from gymnasium.envs.registration import load_env_creator

        entry = gym.spec(env_id).entry_point
        creator = load_env_creator(entry) if isinstance(entry, str) else entry
        modes = getattr(creator, "metadata", {}).get("render_modes")
        if modes is None or render_mode in modes:  # unknown: the env answers itself
            return gym.make(env_id, render_mode=render_mode)
        if render_mode == "human" and "rgb_array" in modes:
            self._own_window = True
            return gym.make(env_id, render_mode="rgb_array")
        raise ValueError(f"render_mode={render_mode!r}: {env_id} renders only {list(modes)}")

    def _render_modes(self) -> list[str]:
        """The render modes this env offers: ``rgb_array`` where the base env renders it (a
        simulator of your own: where it has the hook ``render``), ``human`` where the base env has a
        window of its own or an ``rgb_array`` frame to show."""
        base = list(self.env.metadata.get("render_modes") or [])  # a SnapshotEnv's: none without the hook
        return [m for m in ("rgb_array", "human") if m in base or (m == "human" and "rgb_array" in base)]

    def _env_dt(self, step_dt: float | None) -> float:
        """The env's step: its ``dt`` (``tau`` for CartPole), else ``step_dt``."""
        u = self.env.unwrapped
        for attr in ("dt", "tau"):  # MuJoCo and most envs: dt; CartPole: tau
            v = getattr(u, attr, None)
            if isinstance(v, (int, float)) and math.isfinite(v) and v > 0:
                return float(v)
        if step_dt is not None:
            return float(step_dt)
        raise ValueError(
            f"{self.env_name} states no step length (an attribute dt or tau on the unwrapped env); "
            "give step_dt (the seconds one env step advances)"
        )

    @property
    def driver(self):
        """The driver as it was given (its own attributes, e.g. an episode's ``target``, are read by views)."""
        return self._driver_obj

    def render_frame(self) -> np.ndarray:
        return np.asarray(self.env.render())

    def render(self):
        if self.render_mode == "human" and not self._own_window:
            return self.env.render()  # the env's own window
        return super().render()

    def _begin(self, rng: np.random.Generator) -> None:
        for obj in (self._driver_obj, self._safe_obj, self._success):
            begin = getattr(obj, "begin_episode", None)
            if callable(begin):
                begin(rng)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.check_options(options)
        obs, _ = self.env.reset(seed=int(self.np_random.integers(2**31)))
        self._begin(np.random.default_rng(int(self.np_random.integers(2**63))))
        self._obs = obs
        self._carry = 0.0
        self.scene = _RUNNING  # an episode runs (risk_scene gives the adapter's scene)
        self.begin_episode()
        self.begin_statistics()
        info = {"nominal_control": self.update_nominal()}
        self.clock.start()
        return obs, info

    def driver_control(self) -> np.ndarray:
        return self._acts.control(self._acts.check(self._driver(self._obs), f"the driver {_name(self._driver)}"))

    def _failed(self, obs, terminated: bool) -> bool:
        return bool(self._failure(obs)) if self._failure is not None else bool(terminated)

    def simulate(self, duration: float, active: bool, control, compute_time: float = 0.0):
        self.check_interval(duration)
        self._carry += duration
        n = int(math.floor(self._carry / self.dt + 1e-9))
        self._carry = max(0.0, self._carry - n * self.dt)
        action = self._acts.action(control if active else self._nominal)
        outcome, reward, ended = None, 0.0, False
        for _ in range(n):
            obs, r, terminated, truncated, _ = self.env.step(action)
            self._obs = obs
            reward += float(r)
            if self._failed(obs, terminated):
                outcome = "collision"
            elif self._success(obs):
                outcome = "goal"
            ended = terminated or truncated
            if outcome is not None or ended:
                break
        self.count_interval(duration, active, compute_time)
        info: dict = {}
        terminated, truncated = self.end_interval(outcome, reward, info, truncate=ended)
        return self._obs, reward, terminated, truncated, info

    def final_speed(self):
        return None

    def episode_statistics(self, outcome: str | None = None) -> dict:
        """Table I's statistics, without ``final_speed`` (an optional one: there is no vehicle)."""
        stats = super().episode_statistics(outcome)
        del stats["final_speed"]
        return stats

    def close(self):
        self.env.close()
        if self._sampler is not None:
            self._sampler[0].close()
        super().close()

    # ------------------------------------------------------------------ labelling hooks
    def _adapter_of(self, env: gym.Env, command: str | None = None) -> AdaptedEnv:
        if isinstance(env, SnapshotEnv):
            return SnapshotAdapter(env, command)
        from rmm_envs.adapters import adapt

        return adapt(env)

    def _adapted(self) -> AdaptedEnv:
        if self._adapter is None:
            self._adapter = self._adapter_of(self.env)
        return self._adapter

    def require_labelling(self, command: str) -> None:
        """``TypeError`` naming ``command`` and the first hook it needs that the env lacks (a
        simulator of your own: ``state_failed``, ``sample_states``; another env: its risk adapter)."""
        if self.simulator is not None:
            require_hooks(self.simulator, ("state_failed", "sample_states"), command, self.env_name)
        self._adapted()

    @property
    def default_horizon(self) -> float:
        """The risk adapter's default horizon ``t`` (what ``rmm-datagen`` uses without ``--horizon``)."""
        return self._adapted().scene.default_horizon

    def risk_scene(self):
        self.require_episode()
        return self._adapted().scene

    @property
    def true_state(self) -> np.ndarray:
        return self._adapted().true_state

    def observe_states(self, states, rng=None) -> np.ndarray:
        return self._adapted().observe_states(states, rng)

    def privileged(self) -> dict:
        return self._adapted().privileged()

    def dataset_notes(self) -> dict:
        return self._adapted().dataset_notes()

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Half from the adapter's sampler, half from states the driver alone visits (see the module docstring)."""
        own = self._adapted().sample_states(rng, n // 2)
        return np.vstack([own, self._visited(rng, n - n // 2)])

    def _visited(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if self._sampler is None:
            twin: gym.Env
            if isinstance(self.env, SnapshotEnv):
                twin = copy.deepcopy(self.env)  # the simulator copied, in its state when guarded() got it
            elif self.env.spec is None:
                raise TypeError(f"{self.env_name}: sampling visited states needs an env made by gym.make (a spec)")
            else:
                twin = gym.make(self.env.spec)
            self._sampler = (twin, self._adapter_of(twin))
        twin, adapter = self._sampler
        driver = copy.deepcopy(self._driver_obj)
        policy = _policy(driver, "driver")
        # a simulator of one's own never truncates: its episodes end at max_episode_sim_time
        limit = math.ceil(self.max_episode_sim_time / self.dt - 1e-9) if isinstance(twin, SnapshotEnv) else math.inf
        pool: list[np.ndarray] = []
        while len(pool) < max(n, 1) * 2:
            obs, _ = twin.reset(seed=int(rng.integers(2**31)))
            begin = getattr(driver, "begin_episode", None)
            if callable(begin):
                begin(rng)
            pool.append(adapter.true_state)
            k = 0
            while k < limit:
                k += 1
                a = self._acts.check(policy(obs), f"the driver {_name(policy)}")
                obs, _, terminated, truncated, _ = twin.step(a)
                if self._failed(obs, terminated):
                    break
                pool.append(adapter.true_state)
                if terminated or truncated:
                    break
        states = np.array(pool)
        states = states[~adapter.scene.state_failed(states)]
        return states[rng.choice(states.shape[0], size=n, replace=states.shape[0] < n)]


def guarded(env, driver, safe_default, success, failure=None, **kwargs) -> DrivenGuardedEnv:
    """The blocking guarded env of ``env``, a Gymnasium env, its id or a simulator of your own
    (see the module docstring for every argument)."""
    return DrivenGuardedEnv(env, driver, safe_default, success, failure=failure, **kwargs)


def parallel(
    env,
    driver,
    safe_default,
    success,
    failure=None,
    time_accel: float = TIME_ACCEL,
    base_step: float | None = None,
    clock=None,
    **kwargs,
):
    """The non-blocking twin of :func:`guarded`: the same env under
    :class:`rmm_envs.wrappers.NonBlockingStepping`.  ``base_step`` defaults to ``step_dt`` when
    that is given, else to the env's own step; both given and different is a ``ValueError``."""
    step_dt = kwargs.get("step_dt")
    if base_step is not None and step_dt is not None and float(base_step) != float(step_dt):
        raise ValueError(
            f"parallel(): base_step={base_step!r} and step_dt={step_dt!r} both set the seconds of a base step; "
            "give one of them"
        )
    inner = DrivenGuardedEnv(env, driver, safe_default, success, failure=failure, **kwargs)
    return NonBlockingStepping(
        inner, time_accel=time_accel, base_step=inner.step_dt if base_step is None else base_step, clock=clock
    )
