"""Running episodes: one guardian, one seeded episode, in a worker process or a Ray task.

Episode ``i`` of a run uses the env seed derived from the run's ``--seed`` (every agent meets
the same configurations; the original drew seeds unseeded, with repeats).  The guardian's
``reset`` (e.g. an HJ solve) is timed as ``precompute_time`` and, as in the paper's reported
HJ row, not charged to the episode's clock unless ``charge_precompute`` is set.

A guardian that raises (in ``reset``, ``act`` or ``stats``, or with ``sys.exit``), or an
episode exceeding ``episode_timeout`` seconds of wall time, ends that episode with outcome
``error``, the message and its kind (``guardian`` or ``timeout``, see the store); the run goes
on.  The time limit is a ``SIGALRM`` timer in the worker, so it interrupts Python code; a
call stuck in compiled code is ended by the parent, which kills the worker after
:func:`hard_timeout` seconds and records the episode as ``lost_worker``.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import signal
import statistics
import time
import traceback

import numpy as np

__all__ = ["EpisodeTimeout", "episode_seed", "hard_timeout", "lost_episode", "run_episode", "run_key"]

_SEED_DOMAIN = 0xBE7C  # keeps episode seeds apart from rmm-datagen's configuration seeds


def episode_seed(seed: int, episode: int) -> int:
    return int(np.random.SeedSequence([int(seed), _SEED_DOMAIN], spawn_key=(int(episode),)).generate_state(1)[0])


def run_key(config: dict) -> str:
    return hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:16]


class EpisodeTimeout(Exception):
    pass


def hard_timeout(episode_timeout: float) -> float:
    """Seconds after which the parent kills a worker that has not returned its episode: the
    episode's own limit, plus a quarter and 30 s, so the in-worker timer always fires first
    when it can."""
    return 1.25 * float(episode_timeout) + 30.0


def lost_episode(task: dict, cause: str) -> dict:
    """The store's row for an episode whose worker died: an ``error`` of kind ``lost_worker``."""
    return {"run_key": task["run_key"], "episode": task["episode"], "agent": task["agent"], "seed": task["seed"],
            "outcome": "error", "error_kind": "lost_worker", "error": f"lost: {cause}"[:2000], "finished": time.time()}


def _alarm(signum, frame):
    raise EpisodeTimeout("episode time limit exceeded")


_CACHE: dict = {}


def _env(env_id: str, env_kwargs: dict):
    key = ("env", env_id, json.dumps(env_kwargs, sort_keys=True))
    if key not in _CACHE:
        import gymnasium as gym

        import rmm_envs  # noqa: F401

        _CACHE[key] = gym.make(env_id, **env_kwargs)
    return _CACHE[key]


def _guardian(agent: str, agent_kwargs: dict):
    key = ("guardian", agent, json.dumps(agent_kwargs, sort_keys=True))
    if key not in _CACHE:
        from guardians import make_guardian

        _CACHE[key] = make_guardian(agent, **agent_kwargs)
    return _CACHE[key]


def run_episode(task: dict) -> dict:
    """Run one episode; ``task`` holds run_key, agent, agent_kwargs, env_id, env_kwargs,
    episode, seed, episode_timeout, charge_precompute and optionally kernel_threads (threads
    for the compiled HJ kernel; 1 when several workers already share the cores).  Returns the
    store's episode row."""
    if task.get("kernel_threads"):
        os.environ["RMM_HJ_THREADS"] = str(int(task["kernel_threads"]))
    row = {"run_key": task["run_key"], "episode": task["episode"], "agent": task["agent"], "seed": task["seed"]}
    t_start = time.perf_counter()
    timeout = task.get("episode_timeout")
    use_alarm = bool(timeout) and hasattr(signal, "setitimer")
    old = None
    decisions: list[float] = []
    guardian = None
    try:
        if use_alarm:
            try:
                old = signal.signal(signal.SIGALRM, _alarm)
                signal.setitimer(signal.ITIMER_REAL, float(timeout))
            except ValueError:  # not the main thread (e.g. some Ray setups): check in the loop only
                use_alarm = False
        env = _env(task["env_id"], task["env_kwargs"])
        guardian = _guardian(task["agent"], task["agent_kwargs"])
        obs, info = env.reset(seed=task["seed"])
        t0 = time.perf_counter()
        guardian.reset(seed=task["seed"], observation_space=env.observation_space, action_space=env.action_space,
                       privileged=env.unwrapped.privileged if getattr(guardian, "privileged", False) else None)
        row["precompute_time"] = time.perf_counter() - t0
        clock = env.get_wrapper_attr("clock")
        if task.get("charge_precompute"):
            pass  # the clock keeps running: the solve counts as thinking time on the first step
        else:
            clock.start()
        while True:
            t0 = time.perf_counter()
            action = guardian.act(obs, info)
            decisions.append(time.perf_counter() - t0)
            obs, reward, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                break
            if timeout and time.perf_counter() - t_start > timeout:
                raise EpisodeTimeout("episode time limit exceeded")
        ep = info["episode"]
        row.update(
            outcome=info["outcome"], steps=ep["n_env_steps"], active_steps=ep["n_active_ctrl_env_steps"],
            sim_time=ep["cum_sim_time"], active_sim_time=ep["active_ctrl_sim_time"],
            compute_time=ep["cum_compute_time"], avg_compute_time=ep["avg_compute_time"],
            final_speed=ep["final_speed"], cum_reward=ep["cum_reward"],
        )
    except (Exception, SystemExit) as e:  # recorded, the run goes on
        row["outcome"] = "error"
        row["error_kind"] = "timeout" if isinstance(e, EpisodeTimeout) else "guardian"
        row["error"] = f"{type(e).__name__}: {e}"[:500] + ("" if isinstance(e, EpisodeTimeout) else "\n" + traceback.format_exc(limit=3)[-1500:])
        _CACHE.pop(("guardian", task["agent"], json.dumps(task["agent_kwargs"], sort_keys=True)), None)
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            if old is not None:
                signal.signal(signal.SIGALRM, old)
    if decisions:
        row["decision_mean"] = statistics.fmean(decisions)
        row["decision_std"] = statistics.pstdev(decisions) if len(decisions) > 1 else 0.0
        row["decision_max"] = max(decisions)
    try:  # a guardian's stats() failing is its error, like act() failing
        stats = guardian.stats() if guardian is not None and hasattr(guardian, "stats") else {}
        row["qp_fallbacks"] = int(stats.get("qp_fallbacks", 0))
        row["nan_states"] = int(stats.get("nan_states", 0))
        row["guardian_stats"] = json.dumps({k: v for k, v in stats.items() if isinstance(v, (int, float)) and math.isfinite(v)})
    except (Exception, SystemExit) as e:
        if row["outcome"] != "error":
            row["outcome"], row["error_kind"], row["error"] = "error", "guardian", ""
        row["error"] = (f"{task['agent']}.stats() raised {type(e).__name__}: {e}"[:500] + "\n" + traceback.format_exc(limit=3)[-1500:]
                        + ("\n" + row["error"] if row["error"] else ""))
        _CACHE.pop(("guardian", task["agent"], json.dumps(task["agent_kwargs"], sort_keys=True)), None)
    row["wall_time"] = time.perf_counter() - t_start
    row["finished"] = time.time()
    return row
