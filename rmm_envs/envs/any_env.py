"""Parallel autonomy around any Gymnasium env: :func:`guarded` and :class:`GuardedAnyEnv`.

Give an env (a Gymnasium env, or a simulator of your own written against the snapshot protocol,
see *Simulators of your own* below), a **driver** that controls it by default, a **safe default**
and a **success** test, and get an env with the contract of :mod:`rmm_envs.autonomy` (the one every guardian and
``rmm-bench`` speak), built on the same skeleton as the package's own guarded envs
(:class:`rmm_envs.envs.guarded.GuardedEnv`)::

    from rmm_envs.envs.any_env import guarded
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
``disturbances``
    Sensor noise (an observation space with a layout, ``rmm_envs.autonomy.ObservationBox``) and
    actuation error on the control (:mod:`rmm_envs.disturbances`; off by default); the driver
    and the tests read the true observation.

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
against the snapshot protocol plus optional hooks, all listed in
:data:`rmm_envs.envs.simulator.SIMULATOR_HOOKS` (the tutorial ``docs/tutorials/own-simulator.md``
prints the table); :class:`rmm_envs.envs.simulator.SnapshotEnv` makes it a Gymnasium env, and
its labels come from :class:`rmm_envs.adapters.SnapshotScene` (batched through ``step_batch``
where it has one).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator

from rmm_envs.autonomy import GENERIC, GuardianActionSpace
from rmm_envs.clocks import make_clock
from rmm_envs.envs.any_env_labels import AnyEnvLabels
from rmm_envs.envs.given import (
    Actions,
    GivenSafeDefault,
    as_policy,
    callable_name,
    control_names,
    given_failure,
    given_safe_default,
)
from rmm_envs.envs.guarded import GuardedEnv, Motion
from rmm_envs.envs.simulator import (
    SIMULATOR_HOOKS,
    SimulatorHook,
    SnapshotEnv,
    hooks_table,
    is_simulator,
    require_hooks,
)
from rmm_envs.starts import StartAssessment
from rmm_envs.wrappers.nonblocking import TIME_ACCEL, NonBlockingStepping

__all__ = [
    "SIMULATOR_HOOKS",
    "GuardedAnyEnv",
    "GivenSafeDefault",
    "SimulatorHook",
    "SnapshotEnv",
    "guarded",
    "hooks_table",
    "parallel",
    "require_hooks",
]

#: ``self.scene`` while an episode runs (``None`` before the first ``reset``, as for every env of
#: the package); :meth:`GuardedAnyEnv.risk_scene` gives the risk adapter's scene instead
_RUNNING = "running"


class GuardedAnyEnv(AnyEnvLabels, GuardedEnv):
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
        disturbances=None,
    ) -> None:

        if render_mode not in (None, "rgb_array", "human"):
            raise ValueError(f"render_mode must be None, 'rgb_array' or 'human', got {render_mode!r}")
        if step_dt is not None:
            try:
                ok = not isinstance(step_dt, bool) and math.isfinite(float(step_dt)) and float(step_dt) > 0
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"step_dt must be a finite number of seconds > 0, got {step_dt!r}")
        self.simulator = env if is_simulator(env) else None
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
        self._acts = Actions(self.env.action_space, self.env_name)
        self._driver = as_policy(driver, "driver")
        self._driver_obj = driver
        if not callable(success):
            raise TypeError(f"success must be a callable success(obs) -> bool, got {success!r}")
        self._success = success
        self._failure = given_failure(failure, self.env, self.env_name, simulator=self.simulator is not None)
        self._safe_obj = safe_default
        safe = given_safe_default(safe_default, self._acts)
        names = control_names(controls, self._acts)
        self.action_space = GuardianActionSpace(
            names, self._acts.low, self._acts.high, safe_default=safe, dynamics_name=GENERIC
        )
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
        self._adapter = None
        self._sampler = None
        self.set_disturbances(disturbances)

    def _start_doomed(self, env) -> StartAssessment:
        """The simulator's own doomed-start test of the state it starts from."""
        sim = self.simulator
        assert sim is not None  # set only for a simulator of one's own
        saved = np.asarray(sim.get_state(), dtype=np.float64).copy()
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

    def begin(self, options: dict) -> None:
        obs, _ = self.env.reset(seed=int(self.np_random.integers(2**31)))
        self._begin(np.random.default_rng(int(self.np_random.integers(2**63))))
        self._obs = obs
        self._carry = 0.0
        self.scene = _RUNNING  # type: ignore[assignment]  # an episode runs (risk_scene gives the adapter's scene)
        return None  # the env shows its observation, not a state

    def observe(self):
        return self.sensed(self._obs, self._sim_time)

    def render_step(self) -> None:
        """In ``render_mode="human"`` the frames this env shows (the base env's own window shows itself)."""
        if self.render_mode == "human" and self._own_window:
            self.render()

    def driver_control(self) -> np.ndarray:
        return self._acts.control(
            self._acts.check(self._driver(self._obs), f"the driver {callable_name(self._driver)}")
        )

    def _failed(self, obs, terminated: bool) -> bool:
        return bool(self._failure(obs)) if self._failure is not None else bool(terminated)

    def advance(self, duration: float, active: bool, control) -> Motion:
        """The base env's steps of ``dt`` that fit in the interval (the remainder carried to the
        next), under one held action, stopped at the first failure or success."""
        self._carry += duration
        n = int(math.floor(self._carry / self.dt + 1e-9))
        self._carry = max(0.0, self._carry - n * self.dt)
        ctrl = np.asarray(control if active else self._nominal, dtype=float)
        if self.moves_plant:  # the actuators' control (sim time at the interval's start)
            ctrl = self.actuated(ctrl, self._sim_time)
        action = self._acts.action(ctrl)
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
        return Motion(outcome, ctrl, reward=reward, ended=ended)

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


def guarded(env, driver, safe_default, success, failure=None, **kwargs) -> GuardedAnyEnv:
    """The blocking guarded env of ``env``, a Gymnasium env, its id or a simulator of your own
    (see the module docstring for every argument)."""
    return GuardedAnyEnv(env, driver, safe_default, success, failure=failure, **kwargs)


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
    :class:`rmm_envs.wrappers.NonBlockingStepping` (what a system's ``parallel_env`` entry point
    returns; a built-in system's is made by :func:`rmm_envs.envs.guarded.parallel_twin`).
    ``base_step`` defaults to ``step_dt`` when that is given, else to the env's own step; both
    given and different is a ``ValueError``."""
    step_dt = kwargs.get("step_dt")
    if base_step is not None and step_dt is not None and float(base_step) != float(step_dt):
        raise ValueError(
            f"parallel(): base_step={base_step!r} and step_dt={step_dt!r} both set the seconds of a base step; "
            "give one of them"
        )
    inner = GuardedAnyEnv(env, driver, safe_default, success, failure=failure, **kwargs)
    return NonBlockingStepping(
        inner, time_accel=time_accel, base_step=inner.step_dt if base_step is None else base_step, clock=clock
    )
