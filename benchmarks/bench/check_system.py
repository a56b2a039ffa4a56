"""``rmm-bench check-system ENV``: a pre-flight check of a system before hours of labels and runs.

One line per check, each ``ok``, ``--`` (optional and absent: what that leaves out) or ``FAIL``
(with the reason), then the labelling rate and what a dataset of the requested size will cost:

* ``env``: the env is made with its options (``--env-opt``);
* ``contract``: it offers the parallel-autonomy contract ``rmm-bench`` runs guardians on;
* ``hooks``: for a simulator of your own, every hook of ``rmm_envs.envs.any_env.SIMULATOR_HOOKS``
  present or its default (for the package's envs, the labelling protocol);
* ``determinism``: two episodes from one seed under the driver alone, on a fixed clock, give the
  same observations, rewards and outcome, bit for bit;
* ``render``: a frame can be drawn (a view of the package, or the env's ``rgb_array`` frame);
* ``doomed starts``: whether starts are assessed (Table I's avoidable-collision column);
* ``labels``: ``--probe-states`` states labelled as ``rmm-datagen`` would (the same tree and
  horizon), the rate per process, and the time ``--configs`` x ``--samples-per-config`` labels
  take on ``--workers`` processes.

Exit status: 0 when nothing failed, 1 when a check failed, 2 for bad input (an unknown env).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time

import gymnasium as gym
import numpy as np

from rmm_bench.options import env_opt_option, parse_env_opts
from rmm_bench.run_checks import check_env_contract, env_arguments
from rmm_envs.env_plugins import resolve_env_id
from rmm_envs.envs.any_env import SIMULATOR_HOOKS
from rmm_envs.risk.estimator import RiskEstimator
from rmm_envs.risk.labelling import DatagenConfig, labelled_env
from rmm_envs.risk.protocol import check_labelled_env
from rmm_envs.starts import has_doomed_test
from rmm_envs.views import view_for

__all__ = ["build_parser", "check_system", "cmd"]

OK, ABSENT, FAIL = "ok", "--", "FAIL"


def _make(env_id: str, opts: dict, **extra):
    kwargs = dict(opts)
    if "clock" in env_arguments(env_id) and "clock" not in kwargs:
        kwargs["clock"] = "fixed:1"  # reproducible: the same bits twice
    return gym.make(env_id, **kwargs, **extra)


def _episode_digest(env, seed: int, steps: int) -> tuple[str, str]:
    h = hashlib.sha256()
    obs, _ = env.reset(seed=seed)
    inactive = getattr(env.action_space, "inactive", None)
    action = inactive() if callable(inactive) else None
    outcome = "running"
    for _ in range(steps):
        h.update(np.ascontiguousarray(np.asarray(gym.spaces.flatten(env.observation_space, obs))).tobytes())
        obs, reward, terminated, truncated, info = env.step(action)
        h.update(np.float64(reward).tobytes())
        if terminated or truncated:
            outcome = str(info.get("episode_stats", {}).get("outcome", "ended"))
            break
    return h.hexdigest(), outcome


def _hooks(env) -> tuple[str, str]:
    sim = getattr(env.unwrapped, "simulator", None)
    if sim is not None:
        missing = [h.name for h in SIMULATOR_HOOKS.values() if getattr(sim, h.name, None) is None]
        required = [n for n in missing if SIMULATOR_HOOKS[n].default is None]
        defaults = [n for n in missing if SIMULATOR_HOOKS[n].default is not None]
        detail = f"{len(SIMULATOR_HOOKS) - len(missing)} of {len(SIMULATOR_HOOKS)} hooks"
        if defaults:
            detail += f"; defaults for {', '.join(defaults)}"
        if required:
            return FAIL if {"action_space", "get_state", "set_state", "step"} & set(required) else ABSENT, (
                f"{detail}; missing {', '.join(required)} (needed by "
                + "; ".join(f"{n}: {SIMULATOR_HOOKS[n].needed_by}" for n in required)
                + ")"
            )
        return OK, detail
    try:
        check_labelled_env(env.unwrapped)
        return OK, "the labelling protocol (rmm_envs.risk.LabelledEnv)"
    except TypeError as e:
        return ABSENT, f"labelled through a risk adapter, if one serves it ({e})"


def check_system(env_id: str, opts: dict, configs: int, samples: int, workers: int, probe: int, seed: int = 0):
    """The checks as ``(name, status, detail)`` rows, and the labelling rate (labels/s, or None)."""
    rows: list[tuple[str, str, str]] = []
    env_id = resolve_env_id(env_id)
    try:
        env = _make(env_id, opts)
    except Exception as e:  # noqa: BLE001 - the constructor's own error, in one line
        rows.append(("env", FAIL, f"{type(e).__name__}: {e}"))
        return rows, None
    rows.append(("env", OK, f"{env_id} {json.dumps(opts, sort_keys=True) if opts else ''}".strip()))
    try:
        check_env_contract(env_id, env)
        rows.append(("contract", OK, "the parallel-autonomy contract (rmm_envs.autonomy)"))
    except ValueError as e:
        rows.append(("contract", FAIL, str(e)))
    rows.append(("hooks", *_hooks(env)))
    steps = 200
    try:
        first, second = _episode_digest(env, seed, steps), _episode_digest(env, seed, steps)
        again = _make(env_id, opts)
        third = _episode_digest(again, seed, steps)
        again.close()
        same = first == second == third
        rows.append(
            (
                "determinism",
                OK if same else FAIL,
                f"seed {seed}, {steps} steps at most, driver alone: "
                + ("the same bits twice and in a new env" if same else "episodes from one seed differ"),
            )
        )
    except Exception as e:  # noqa: BLE001
        rows.append(("determinism", FAIL, f"{type(e).__name__}: {e}"))
    try:
        try:
            view = view_for(env, 128)
        except ValueError:
            drawn = _make(env_id, opts, render_mode="rgb_array")
            view = view_for(drawn, 128)
            drawn.close()
        rows.append(("render", OK, type(view).__name__))
    except Exception as e:  # noqa: BLE001
        rows.append(("render", ABSENT, f"replay cannot draw it: {type(e).__name__}: {e}"))
    env.reset(seed=seed)
    doomed = has_doomed_test(env)
    rows.append(
        (
            "doomed starts",
            OK if doomed else ABSENT,
            "assessed" if doomed else "not assessed: Table I's avoidable-collision columns stay empty",
        )
    )
    env.close()
    rate = None
    try:
        cfg = DatagenConfig(env_id=env_id, configs=1, samples_per_config=probe, seed=seed, env_kwargs=dict(opts))
        hooks = labelled_env(cfg)
        rng = np.random.default_rng(seed)
        hooks.reset(seed=seed)
        states = hooks.sample_states(rng, probe)
        est = RiskEstimator(hooks.risk_scene(), **cfg.estimator_params())
        est.estimate(states[:1], rng)  # compile and warm caches: not part of the rate
        rate = _label_rate(est, states, rng)
        total = configs * samples
        hours = total / (rate * workers) / 3600
        rows.append(
            (
                "labels",
                OK,
                f"{rate:.0f} labels/s per process ({probe} states, n = {cfg.branches}, m = {cfg.depth}, t = "
                f"{cfg.resolved_horizon():g} s); {configs} x {samples} = {total} labels on {workers} process"
                f"{'es' if workers > 1 else ''}: about {_duration(hours * 3600)}",
            )
        )
    except Exception as e:  # noqa: BLE001 - what rmm-datagen would stop on
        rows.append(("labels", FAIL, f"{type(e).__name__}: {e}".split("\n")[0]))
    return rows, rate


def _label_rate(est: RiskEstimator, states: np.ndarray, rng: np.random.Generator, min_seconds: float = 0.2) -> float:
    """Labels/s of ``states``, the median of runs repeated until ``min_seconds`` have passed (one
    run of a slow simulator; many of a batched one, whose run is shorter than a busy machine's noise)."""
    rates: list[float] = []
    start = time.perf_counter()
    while not rates or time.perf_counter() - start < min_seconds:
        t0 = time.perf_counter()
        est.estimate(states, rng)
        rates.append(states.shape[0] / (time.perf_counter() - t0))
    return float(np.median(rates))


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        parents=[env_opt_option()],
        prog="rmm-bench check-system",
        description="Pre-flight check of a system (an env id, or module:Id): the contract, the hooks, "
        "determinism under a seed, rendering, doomed-start assessment, and the labelling rate with the time a "
        "dataset of the requested size will take.",
    )
    p.add_argument("env", metavar="ENV", help="a registered env id, or module:Id for an env that module registers")
    p.add_argument("--configs", type=int, default=274, help="rmm-datagen --configs to estimate (default: %(default)s)")
    p.add_argument(
        "--samples-per-config",
        type=int,
        default=128,
        help="rmm-datagen --samples-per-config to estimate (default: %(default)s)",
    )
    p.add_argument("--workers", type=int, default=1, help="processes the estimate assumes (default: %(default)s)")
    p.add_argument("--probe-states", type=int, default=8, help="states labelled to measure the rate (default: 8)")
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="master seed of the episodes checked, and of the states labelled (default: %(default)s)",
    )
    return p


def cmd(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    for flag, value in (
        ("--configs", args.configs),
        ("--samples-per-config", args.samples_per_config),
        ("--workers", args.workers),
        ("--probe-states", args.probe_states),
    ):
        if value < 1:
            raise ValueError(f"{flag} must be an integer >= 1, got {value}")
    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    opts = parse_env_opts(args.env_opt)
    rows, _ = check_system(
        args.env, opts, args.configs, args.samples_per_config, args.workers, args.probe_states, args.seed
    )
    width = max(len(r[0]) for r in rows)
    for name, status, detail in rows:
        print(f"{status:4} {name:<{width}}  {detail}")
    failed = [r[0] for r in rows if r[1] == FAIL]
    print(
        f"{len(rows) - len(failed)} of {len(rows)} checks passed" + (f"; failed: {', '.join(failed)}" if failed else "")
    )
    return 1 if failed else 0
