"""Parallel autonomy around any Gymnasium env: :func:`guarded` and :class:`DrivenGuardedEnv`.

Give an env, a **driver** that controls it by default, a **safe default** and a **success**
test, and get an env with the contract of :mod:`rmm_envs.autonomy` (the one every guardian and
``rmm-bench`` speak), built on the same skeleton as the package's own guarded envs
(:class:`rmm_envs.envs.guarded.GuardedEnv`)::

    from rmm_envs.envs.driven import guarded
    env = guarded("CartPole-v1", driver=my_policy, safe_default=balance, success=at_target)

Arguments (each refused by name, with what was expected, when it does not fit):

``env``
    A Gymnasium env or its id (``gym.make``'d).  Its action space is ``Discrete(n)`` or a
    bounded 1-D ``Box``; its observation is what the guardian reads, unchanged.
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
    unhealthy state); any other env is refused unless told: ``"terminated"`` (its termination
    is failure) or ``failure(obs) -> bool``.  A failed step ends the episode as
    ``"collision"``, with ``info["cost"] = 1.0``.
``controls``
    The guardian action's control fields (default ``("u0", "u1", ...)``, one per action
    component; one for ``Discrete``).
``step_dt``, ``max_episode_sim_time``
    Seconds per blocking step (default: the env's own step) and per episode (default: the
    env's ``max_episode_steps`` times its step).

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
"""

from __future__ import annotations

import copy
import math

import gymnasium as gym
import numpy as np

from rmm_envs.autonomy import GENERIC, GuardianActionSpace, SafeDefault
from rmm_envs.envs.guarded import GuardedEnv
from rmm_envs.wrappers.nonblocking import TIME_ACCEL, NonBlockingStepping

__all__ = ["DrivenGuardedEnv", "GivenSafeDefault", "guarded", "parallel"]


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

    metadata = {"render_modes": []}
    render_mode = None

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
    ) -> None:
        from rmm_envs.adapters import termination_is_failure
        from rmm_envs.clocks import make_clock

        self.env = gym.make(env) if isinstance(env, str) else env
        if not isinstance(self.env, gym.Env):
            raise TypeError(f"env must be a gymnasium.Env or a registered env id, got {env!r}")
        spec = getattr(self.env, "spec", None)
        self.env_name = spec.id if getattr(spec, "id", None) else type(self.env.unwrapped).__name__
        self._acts = _Actions(self.env.action_space, self.env_name)
        self._driver = _policy(driver, "driver")
        self._driver_obj = driver
        if not callable(success):
            raise TypeError(f"success must be a callable success(obs) -> bool, got {success!r}")
        self._success = success
        if failure is None and not termination_is_failure(self.env):
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
        self.dt = self._env_dt()
        self.step_dt = self.dt if step_dt is None else float(step_dt)
        steps = getattr(spec, "max_episode_steps", None)
        if max_episode_sim_time is None and steps is None:
            raise ValueError(f"{self.env_name} has no max_episode_steps; give max_episode_sim_time (seconds)")
        self.max_episode_sim_time = float(max_episode_sim_time if max_episode_sim_time is not None else steps * self.dt)
        for name, v in (("step_dt", self.step_dt), ("max_episode_sim_time", self.max_episode_sim_time)):
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number of seconds > 0, got {v!r}")
        self.clock = make_clock(clock)
        self._adapter = None
        self._sampler = None

    # ------------------------------------------------------------------ the env
    def _env_dt(self) -> float:
        u = self.env.unwrapped
        for attr in ("dt", "tau"):  # MuJoCo and most envs: dt; CartPole: tau
            v = getattr(u, attr, None)
            if isinstance(v, (int, float)) and math.isfinite(v) and v > 0:
                return float(v)
        raise ValueError(f"{self.env_name} states no step length (an attribute dt or tau on the unwrapped env)")

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

    # ------------------------------------------------------------------ labelling hooks
    def _adapted(self):
        if self._adapter is None:
            from rmm_envs.adapters import adapt

            self._adapter = adapt(self.env)
        return self._adapter

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
        return {"state": self.true_state}

    def dataset_notes(self) -> dict:
        return self._adapted().dataset_notes()

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Half from the adapter's sampler, half from states the driver alone visits (see the module docstring)."""
        own = self._adapted().sample_states(rng, n // 2)
        return np.vstack([own, self._visited(rng, n - n // 2)])

    def _visited(self, rng: np.random.Generator, n: int) -> np.ndarray:
        from rmm_envs.adapters import adapt

        if self._sampler is None:
            if getattr(self.env, "spec", None) is None:
                raise TypeError(f"{self.env_name}: sampling visited states needs an env made by gym.make (a spec)")
            twin = gym.make(self.env.spec)
            self._sampler = (twin, adapt(twin))
        twin, adapter = self._sampler
        driver = copy.deepcopy(self._driver_obj)
        policy = _policy(driver, "driver")
        pool: list[np.ndarray] = []
        while len(pool) < max(n, 1) * 2:
            obs, _ = twin.reset(seed=int(rng.integers(2**31)))
            begin = getattr(driver, "begin_episode", None)
            if callable(begin):
                begin(rng)
            pool.append(adapter.true_state)
            while True:
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
    """The blocking guarded env of ``env`` (see the module docstring for every argument)."""
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
    :class:`rmm_envs.wrappers.NonBlockingStepping` (``base_step`` defaults to the env's own step)."""

    inner = DrivenGuardedEnv(env, driver, safe_default, success, failure=failure, **kwargs)
    return NonBlockingStepping(
        inner, time_accel=time_accel, base_step=inner.dt if base_step is None else base_step, clock=clock
    )
