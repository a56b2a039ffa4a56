"""Running episodes: one guardian, one seeded episode, in a worker process or a Ray task.

Episode ``i`` of a run uses the env seed derived from the run's ``--seed`` (every agent meets
the same configurations; the original drew seeds unseeded, with repeats).  The guardian's
``reset`` (e.g. an HJ solve) is timed as ``precompute_time`` and, as in the paper's reported
HJ row, not charged to the episode's clock unless ``charge_precompute`` is set.

Before a guardian's first timed decision in a worker, one untimed ``act`` and a second
``reset`` warm it up (:func:`_warm_up`): compiling its kernels is not charged to the episode.

A guardian that raises (in ``reset``, ``act`` or ``stats``, or with ``sys.exit``), or an
episode exceeding ``episode_timeout`` seconds of wall time, ends that episode with outcome
``error``, the message and its kind (``guardian`` or ``timeout``, see the store); the run goes
on.  What the env raises in its ``reset`` or ``step`` (its own code, e.g. a driver) is the env's
error, kind ``env`` (as is an env a worker cannot make, or one ending an episode without the
contract's statistics), never the guardian's; an action of the guardian that the env's action
space refuses stays the guardian's.  A stored traceback keeps its innermost frames, where the
code raised (:func:`_traceback_text`).  A worker whose files (a model, the source of a
``module:Class`` agent's or ``module:Id`` env's module) no longer hash to the run's ``inputs``
runs no episode: each is stored as ``input_changed``, a failure of the run that any rerun
retries.  The
time limit is a ``SIGALRM`` timer in the worker, so it interrupts Python code; a call stuck in
compiled code is ended by the parent, which kills the worker after :func:`hard_timeout` seconds
and records the episode as ``lost_worker``.

The env is driven only through the parallel-autonomy contract (:mod:`rmm_bench.run_checks`):
the result's columns come from the last step's ``info["outcome"]`` and ``info["episode_stats"]``
(:data:`EPISODE_STATISTICS`; ``final_speed`` and ``cum_cost`` are optional).  The guardian is built with the
run's options, plus ``threads`` when the task carries it (see :func:`rmm_bench.run_plan.plan_tasks`).

Clock traces.  For a clocked run (a non-blocking env whose clock is not reproducible: ``wall``
or ``cpu``), :func:`play_episode` also returns every lap the non-blocking wrapper's clock
returned in the episode (read at its end through
:meth:`rmm_envs.wrappers.nonblocking.NonBlockingStepping.episode_laps`); the store keeps them
beside the row.  ``rmm-bench replay`` runs the very same :func:`play_episode` on an env whose
clock plays them back (:class:`rmm_envs.clocks.ReplayClock`).  Columns and guardian
statistics that measure time on this machine are declared in :data:`TIMING_COLUMNS`,
:data:`CLOCK_COLUMNS` and :func:`is_timing_stat`: a replay does not compare them.
"""

from __future__ import annotations

import json
import math
import signal
import statistics
import time
import warnings
from dataclasses import dataclass

import gymnasium as gym
import numpy as np

from rmm_bench.config import (
    EpisodeResult,
    EpisodeTask,
    InputChanged,
    changed_inputs,
    run_input_digests,
    run_key,
)
from rmm_bench.episode_columns import (
    CACHE_STATS,
    CLOCK_COLUMNS,
    EPISODE_STATISTICS,
    REPRODUCIBLE_CLOCKS,
    TIMING_COLUMNS,
    TRACEBACK_CHARS,
    EnvContractError,
    EpisodeTimeout,
    _error_text,
    _statistics,
    _traceback_text,
    is_timing_stat,
)
from rmm_envs.env_plugins import EnvUnavailable, resolve_env_id
from rmm_envs.starts import start_fingerprint
from rmm_envs.user_modules import search_user_folders
from rmm_guardians import make_guardian

__all__ = [
    "TRACEBACK_CHARS",
    "CACHE_STATS",
    "CLOCK_COLUMNS",
    "EPISODE_STATISTICS",
    "REPRODUCIBLE_CLOCKS",
    "TIMING_COLUMNS",
    "EpisodeRecord",
    "EpisodeTimeout",
    "episode_seed",
    "hard_timeout",
    "is_timing_stat",
    "lost_episode",
    "play_episode",
    "run_episode",
    "run_key",
    "run_traced_episode",
]

_SEED_DOMAIN = 0xBE7C  # keeps episode seeds apart from rmm-datagen's configuration seeds


@dataclass(frozen=True)
class EpisodeRecord:
    """What :func:`play_episode` returns: the store's row and, for a clocked run, the laps its
    clock returned (``None``: the run's options reproduce them, or the episode never started)."""

    result: EpisodeResult
    clock_trace: tuple[float, ...] | None = None


def episode_seed(seed: int, episode: int) -> int:
    return int(np.random.SeedSequence([int(seed), _SEED_DOMAIN], spawn_key=(int(episode),)).generate_state(1)[0])


def hard_timeout(episode_timeout: float) -> float:
    """Seconds after which the parent kills a worker that has not returned its episode: the
    episode's own limit, plus a quarter and 30 s, so the in-worker timer always fires first
    when it can."""
    return 1.25 * float(episode_timeout) + 30.0


def lost_episode(task: EpisodeTask, cause: str) -> EpisodeResult:
    """The store's row for an episode whose worker died: an ``error`` of kind ``lost_worker``."""
    return EpisodeResult(
        run_key=task.run_key,
        episode=task.episode,
        agent=task.agent,
        seed=task.seed,
        outcome="error",
        error_kind="lost_worker",
        error=f"lost: {cause}"[:2000],
        finished=time.time(),
    )


def _alarm(signum, frame):
    raise EpisodeTimeout("episode time limit exceeded")


_CACHE: dict = {}


def _env(env_id: str, env_kwargs: dict):
    """The worker's env (built once).  An env this worker cannot register or make is
    :class:`EnvUnavailable`: a failure of the run, not of the guardian (the parent made it)."""
    key = ("env", env_id, json.dumps(env_kwargs, sort_keys=True))
    if key not in _CACHE:
        try:
            _CACHE[key] = gym.make(resolve_env_id(env_id), **env_kwargs)
        except EnvUnavailable as e:
            raise EnvUnavailable(f"in this worker: {e}") from None
        except Exception as e:  # noqa: BLE001 - its registration or constructor failed here, not in the parent
            raise EnvUnavailable(f"in this worker: --env {env_id!r} cannot be made: {type(e).__name__}: {e}") from None
    return _CACHE[key]


def _guardian_key(task: EpisodeTask) -> tuple:
    return (
        "guardian",
        task.agent,
        json.dumps(task.guardian_kwargs(), sort_keys=True),
        json.dumps(task.run.inputs, sort_keys=True),
    )


def guardian_for(task: EpisodeTask):
    """The guardian :func:`play_episode` will use for ``task`` in this process (built once, as
    :func:`_guardian`): :class:`~rmm_bench.config.InputChanged` if its files are not the run's."""
    return _guardian(task)


def _guardian(task: EpisodeTask):
    """The worker's guardian for ``task``, built once; its files must still be those the run was
    keyed with (:class:`InputChanged` otherwise: the episode would mix two models in one run).

    Built without its warnings (e.g. ``lrmm``'s fallback to the paper's threshold): the parent
    built the same guardian before dispatching any episode (:func:`rmm_bench.run_checks.check_runs`)
    and showed them there, once per run; every worker process would repeat them."""
    key = _guardian_key(task)
    if key not in _CACHE:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            guardian = make_guardian(task.agent, env_id=task.run.env_id, **task.guardian_kwargs())
        if task.run.inputs:
            base = task.import_path[0] if task.import_path else None  # module paths are relative to rmm-bench's folder
            changed = changed_inputs(task.run.inputs, run_input_digests(guardian, task.run, base))
            if changed:
                raise InputChanged(
                    f"{changed}: a file changed after the run started, so this episode was not run; "
                    "rerun the command: it starts a new run with the file as it is now"
                )
        _CACHE[key] = guardian
    return _CACHE[key]


def _warm_up(task: EpisodeTask, guardian, obs, info, env) -> None:
    """Once per worker and guardian, before its first timed decision: the guardian's untimed
    ``warm_up`` (one ``act`` on the episode's first observation, and whatever compiled paths
    that decision skips), then ``reset`` again (the episode starts as if it had not happened),
    so compiling or loading compiled code (numba kernels, lazy imports) is never charged to a
    decision.  Skipped under ``--charge-precompute``, which charges all setup."""
    key = ("warm",) + _guardian_key(task)
    if key in _CACHE:
        return
    warm = getattr(guardian, "warm_up", None)
    (warm or guardian.act)(obs, info)
    guardian.reset(
        seed=task.seed,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged if getattr(guardian, "privileged", False) else None,
    )
    _CACHE[key] = True


def _refused_action(env, action) -> bool:
    """Whether the env's action space refuses ``action`` (a guardian's bad action, which the env
    raises on in ``step``: the guardian's error, not the env's)."""
    parse = getattr(getattr(env, "action_space", None), "parse", None)
    if not callable(parse):
        return False
    try:
        parse(action)
    except Exception:  # noqa: BLE001 - any refusal of the action is the guardian's
        return True
    return False


def run_episode(task: EpisodeTask) -> EpisodeResult:
    """Run one episode of ``task`` in this process; returns the store's episode row."""
    return play_episode(task).result


def run_traced_episode(task: EpisodeTask) -> EpisodeRecord:
    """Run one episode of ``task`` in this process; returns its row and clock trace (what ``rmm-bench`` stores)."""
    return play_episode(task)


def _laps(env) -> tuple[float, ...] | None:
    """The episode's clock trace from the non-blocking wrapper, if the env has one and its clock
    is not reproducible from the run's options."""
    try:
        laps = env.get_wrapper_attr("episode_laps")
        clock = env.get_wrapper_attr("clock")
    except AttributeError:  # a blocking env: its clock only times, no trace to keep
        return None
    return None if getattr(clock, "mode", None) in REPRODUCIBLE_CLOCKS else tuple(laps())


def play_episode(task: EpisodeTask, env=None, observer=None) -> EpisodeRecord:
    """Run one episode of ``task`` in this process: the store's episode row and its clock trace.

    ``env``: the env to run it on (``rmm-bench replay`` passes one built with the run's options
    and a :class:`~rmm_envs.clocks.ReplayClock`); default, this worker's env for the run.
    ``observer``: an object with ``begin(env)`` (called after the reset) and ``step(info,
    guardian)`` (after every step), and optionally ``observe(obs)`` (the observation, after each
    of them), for a replay that draws the episode; it must not act on the env.  A run passes
    none: drawing would cost a clocked run's time."""
    t_start = time.perf_counter()
    run = task.run
    timeout = run.episode_timeout
    use_alarm = bool(timeout) and hasattr(signal, "setitimer")
    old = None
    decisions: list[float] = []
    guardian = None
    started = None  # the env, once this episode's reset returned (its laps are this episode's)
    fields: dict = {}
    env_call = None  # "reset" or "step" while the env runs: what it raises is the env's error, not the guardian's
    action = None
    try:
        if use_alarm:
            try:
                old = signal.signal(signal.SIGALRM, _alarm)
                signal.setitimer(signal.ITIMER_REAL, float(timeout))
            except ValueError:  # not the main thread (e.g. some Ray setups): check in the loop only
                use_alarm = False
        if task.import_path:  # the folder rmm-bench ran in: its modules, after the installed packages
            search_user_folders(task.import_path)
        if env is None:
            env = _env(run.env_id, run.env_kwargs)
        guardian = _guardian(task)
        env_call = "reset"
        obs, info = env.reset(seed=task.seed)
        env_call = None
        started = env
        fields["start"] = start_fingerprint(env, obs)
        observe = getattr(observer, "observe", None)  # an observer that also reads the observations
        if observer is not None:
            observer.begin(env)
            if observe is not None:
                observe(obs)
        t0 = time.perf_counter()
        guardian.reset(
            seed=task.seed,
            observation_space=env.observation_space,
            action_space=env.action_space,
            privileged=env.unwrapped.privileged if getattr(guardian, "privileged", False) else None,
        )
        fields["precompute_time"] = time.perf_counter() - t0
        if (
            not run.charge_precompute
        ):  # else the clock keeps running: the solve counts as thinking time on the first step
            _warm_up(task, guardian, obs, info, env)
            env.get_wrapper_attr("clock").start()
        while True:
            t0 = time.perf_counter()
            action = guardian.act(obs, info)
            decisions.append(time.perf_counter() - t0)
            env_call = "step"
            obs, reward, terminated, truncated, info = env.step(action)
            env_call = None
            if observer is not None:
                observer.step(info, guardian)
                if observe is not None:
                    observe(obs)
            if terminated or truncated:
                break
            if timeout and time.perf_counter() - t_start > timeout:
                raise EpisodeTimeout("episode time limit exceeded")
        fields.update(_statistics(run.env_id, info))
    except (Exception, SystemExit) as e:  # recorded, the run goes on
        env_raised = (  # the env's own code (its reset, step, driver) raised; a bad action it refuses is the guardian's
            env_call is not None
            and not isinstance(e, EpisodeTimeout)
            and not (env_call == "step" and _refused_action(env, action))
        )
        error_kind = (
            "timeout"
            if isinstance(e, EpisodeTimeout)
            else "input_changed"
            if isinstance(e, InputChanged)
            else "env"
            if env_raised or isinstance(e, (EnvUnavailable, EnvContractError))
            else "guardian"
        )
        where = f"raised by the env {run.env_id} in its {env_call}(), not by the guardian" if env_raised else ""
        fields.update(outcome="error", error_kind=error_kind, error=_error_text(e, where))
        _CACHE.pop(_guardian_key(task), None)
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            if old is not None:
                signal.signal(signal.SIGALRM, old)
    if decisions:
        fields.update(
            decision_mean=statistics.fmean(decisions),
            decision_std=statistics.pstdev(decisions) if len(decisions) > 1 else 0.0,
            decision_max=max(decisions),
        )
    try:  # a guardian's stats() failing is its error, like act() failing
        stats = guardian.stats() if guardian is not None and hasattr(guardian, "stats") else {}
        fields.update(
            qp_fallbacks=int(stats.get("qp_fallbacks", 0)),
            nan_states=int(stats.get("nan_states", 0)),
            guardian_stats=json.dumps(
                {k: v for k, v in stats.items() if isinstance(v, (int, float)) and math.isfinite(v)}
            ),
        )
    except (Exception, SystemExit) as e:
        earlier = fields.get("error") if fields.get("outcome") == "error" else None
        fields.update(
            outcome="error",
            error_kind=fields.get("error_kind") or "guardian",
            error=(
                f"{task.agent}.stats() raised {type(e).__name__}: {e}"[:500]
                + "\n"
                + _traceback_text(e)
                + ("\n" + earlier if earlier else "")
            ),
        )
        _CACHE.pop(_guardian_key(task), None)
    result = EpisodeResult(
        run_key=task.run_key,
        episode=task.episode,
        agent=task.agent,
        seed=task.seed,
        wall_time=time.perf_counter() - t_start,
        finished=time.time(),
        **fields,
    )
    return EpisodeRecord(result, None if started is None else _laps(started))
