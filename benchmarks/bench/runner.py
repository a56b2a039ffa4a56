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
on.  A worker whose guardian's files (a model) no longer hash to the run's ``inputs`` runs no
episode: each is stored as ``input_changed``, a failure of the run that any rerun retries.  The
time limit is a ``SIGALRM`` timer in the worker, so it interrupts Python code; a call stuck in
compiled code is ended by the parent, which kills the worker after :func:`hard_timeout` seconds
and records the episode as ``lost_worker``.

The env is driven only through the parallel-autonomy contract (:mod:`rmm_bench.checks`):
the result's columns come from the last step's ``info["outcome"]`` and ``info["episode_stats"]``
(:data:`EPISODE_STATISTICS`; ``final_speed`` and ``cum_cost`` are optional).  The guardian is built with the
run's options, plus ``threads`` when the task carries it (see :func:`rmm_bench.run.plan_tasks`).
"""

from __future__ import annotations

import json
import math
import signal
import statistics
import time
import traceback
import warnings
from typing import Any

import numpy as np

from rmm_bench.config import (
    EpisodeResult,
    EpisodeTask,
    InputChanged,
    changed_inputs,
    import_from,
    input_digests,
    run_key,
)
from rmm_envs.envs.guarded import EPISODE_KEY

__all__ = [
    "EPISODE_STATISTICS",
    "EpisodeTimeout",
    "episode_seed",
    "hard_timeout",
    "lost_episode",
    "run_episode",
    "run_key",
]

_SEED_DOMAIN = 0xBE7C  # keeps episode seeds apart from rmm-datagen's configuration seeds

#: The store's columns read from ``info["episode_stats"]`` on the step that ends an episode (the
#: parallel-autonomy contract), column -> statistic.  Every env offering the contract reports these.
EPISODE_STATISTICS = {
    "steps": "n_env_steps",
    "active_steps": "n_active_ctrl_env_steps",
    "sim_time": "cum_sim_time",
    "active_sim_time": "active_ctrl_sim_time",
    "compute_time": "cum_compute_time",
    "avg_compute_time": "avg_compute_time",
    "cum_reward": "cum_reward",
}
#: Statistics an env may report (NULL in the store when it does not): ``final_speed`` (a vehicle's
#: speed) and ``cum_cost`` (the episode's summed ``info["cost"]``, Safety-Gymnasium's safety cost).
OPTIONAL_STATISTICS = {"final_speed": "final_speed", "cost": "cum_cost"}


def episode_seed(seed: int, episode: int) -> int:
    return int(np.random.SeedSequence([int(seed), _SEED_DOMAIN], spawn_key=(int(episode),)).generate_state(1)[0])


class EpisodeTimeout(Exception):
    pass


class EnvContractError(RuntimeError):
    """The env ended an episode without the statistics of the parallel-autonomy contract."""


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
        import gymnasium as gym

        from rmm_envs.env_plugins import EnvUnavailable, resolve_env_id

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


def _guardian(task: EpisodeTask):
    """The worker's guardian for ``task``, built once; its files must still be those the run was
    keyed with (:class:`InputChanged` otherwise: the episode would mix two models in one run).

    Built without its warnings (e.g. ``lrmm``'s fallback to the paper's threshold): the parent
    built the same guardian before dispatching any episode (:func:`rmm_bench.checks.check_runs`)
    and showed them there, once per run; every worker process would repeat them."""
    key = _guardian_key(task)
    if key not in _CACHE:
        from rmm_guardians import make_guardian

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            guardian = make_guardian(task.agent, env_id=task.run.env_id, **task.guardian_kwargs())
        if task.run.inputs:
            changed = changed_inputs(
                task.run.inputs, input_digests(guardian, task.run.agent_kwargs, task.run.env_kwargs)
            )
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


def _statistics(env_id: str, info: dict) -> dict:
    """The store's columns from the last step's ``info`` (the contract's ``outcome`` and ``episode_stats``)."""
    ep: dict[str, Any] = info.get(EPISODE_KEY, {})  # read only when info holds it
    missing = [k for k in ("outcome", EPISODE_KEY) if k not in info] or [
        k for k in EPISODE_STATISTICS.values() if k not in ep
    ]
    if missing:
        where = "info" if EPISODE_KEY not in info or "outcome" not in info else f'info["{EPISODE_KEY}"]'
        raise EnvContractError(
            f"env {env_id} ended an episode without {where} keys {missing} (the parallel-autonomy "
            f"contract: info['outcome'] and info['{EPISODE_KEY}'] with "
            f"{sorted(EPISODE_STATISTICS.values())})"
        )
    out = {col: ep[k] for col, k in EPISODE_STATISTICS.items()}
    out.update({col: ep.get(k) for col, k in OPTIONAL_STATISTICS.items()})
    return {"outcome": info["outcome"], **out}


def _error_text(e: BaseException) -> str:
    return f"{type(e).__name__}: {e}"[:500] + (
        "" if isinstance(e, EpisodeTimeout) else "\n" + traceback.format_exc(limit=3)[-1500:]
    )


def run_episode(task: EpisodeTask) -> EpisodeResult:
    """Run one episode of ``task`` in this process; returns the store's episode row."""
    t_start = time.perf_counter()
    run = task.run
    timeout = run.episode_timeout
    use_alarm = bool(timeout) and hasattr(signal, "setitimer")
    old = None
    decisions: list[float] = []
    guardian = None
    fields: dict = {}
    try:
        if use_alarm:
            try:
                old = signal.signal(signal.SIGALRM, _alarm)
                signal.setitimer(signal.ITIMER_REAL, float(timeout))
            except ValueError:  # not the main thread (e.g. some Ray setups): check in the loop only
                use_alarm = False
        import_from(task.import_path)
        env = _env(run.env_id, run.env_kwargs)
        guardian = _guardian(task)
        obs, info = env.reset(seed=task.seed)
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
            obs, reward, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
            if timeout and time.perf_counter() - t_start > timeout:
                raise EpisodeTimeout("episode time limit exceeded")
        fields.update(_statistics(run.env_id, info))
    except (Exception, SystemExit) as e:  # recorded, the run goes on
        from rmm_envs.env_plugins import EnvUnavailable

        kind = (
            "timeout"
            if isinstance(e, EpisodeTimeout)
            else "input_changed"
            if isinstance(e, InputChanged)
            else "env"
            if isinstance(e, EnvUnavailable)
            else "guardian"
        )
        fields.update(outcome="error", error_kind=kind, error=_error_text(e))
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
                + traceback.format_exc(limit=3)[-1500:]
                + ("\n" + earlier if earlier else "")
            ),
        )
        _CACHE.pop(_guardian_key(task), None)
    return EpisodeResult(
        run_key=task.run_key,
        episode=task.episode,
        agent=task.agent,
        seed=task.seed,
        wall_time=time.perf_counter() - t_start,
        finished=time.time(),
        **fields,
    )
