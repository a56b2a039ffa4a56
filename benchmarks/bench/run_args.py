"""``rmm-bench run`` and ``rmm-bench sweep``: their parsers, and their validation into a :class:`BenchConfig`.

Every option that needs no env or guardian built is checked here, once, and the result is a
frozen :class:`~rmm_bench.config.BenchConfig`; :func:`rmm_bench.run_checks.check_runs`
then builds the env and each guardian before any episode runs.  A bad value raises
ValueError naming the flag and the value (``main`` turns it into one line and exit status 2).
"""

from __future__ import annotations

import argparse
import math
import os

from rmm_bench import run_command
from rmm_bench.config import BenchConfig, parse_shard
from rmm_bench.disturb_sweep import cmd_disturbance_sweep, split_swept
from rmm_bench.options import agent_option, disturb_option, disturbance_opts, env_opt_option, parse_env_opts
from rmm_bench.run_checks import (
    ENV_OPTIONS,
    env_arguments,
    env_default,
    env_parameters,
    parse_agent_opts,
    resolve_agents,
)
from rmm_bench.run_command import cmd_run, cmd_sweep
from rmm_envs.catalog import env_help
from rmm_envs.clocks import make_clock
from rmm_envs.defaults import DEFAULT_ENV
from rmm_envs.wrappers.nonblocking import BASE_STEP, TIME_ACCEL
from rmm_guardians.registry import guardian_set

__all__ = [
    "DEFAULT_ENV",
    "NON_BLOCKING_DEFAULTS",
    "parse_run",
    "parse_sweep",
    "run_cmd",
    "run_options",
    "run_parser",
    "sweep_cmd",
    "sweep_parser",
]

#: the non-blocking stepping options and their defaults (what a blocking env must be left with)
NON_BLOCKING_DEFAULTS = {"time_accel": TIME_ACCEL, "base_step": BASE_STEP}


def run_options(default_agent: str) -> argparse.ArgumentParser:
    """The options ``rmm-bench run`` and ``rmm-bench sweep`` share, as a parent parser."""
    p = argparse.ArgumentParser(
        add_help=False,
        parents=[
            agent_option(
                "guardian name, comma list, 'all' (defaults), 'paper' (the paper's rules), or module:Class "
                f"(default: {default_agent})",
                default=default_agent,
            ),
            env_opt_option(),
            disturb_option(),
        ],
    )
    p.add_argument("--episodes", type=int, default=2048, help="episodes per agent (default: %(default)s)")
    p.add_argument(
        "--env",
        default=DEFAULT_ENV,
        help=f"a registered env id offering the parallel-autonomy contract: {env_help()}, or module:Id for an "
        "env that module registers (default: %(default)s)",
    )
    p.add_argument(
        "--time-accel",
        type=float,
        default=NON_BLOCKING_DEFAULTS["time_accel"],
        help="sim seconds per clock second, for a non-blocking env (default: %(default)s)",
    )
    p.add_argument(
        "--base-step",
        type=float,
        default=None,
        help="sim seconds added every step, for a non-blocking env (default: the env's own, 0.1 for the "
        "package's vehicles, one env step for CartPoleParallel-v0 and InvertedPendulumParallel-v0)",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="master seed; episode i's seed derives from it (default: %(default)s)"
    )
    p.add_argument(
        "--out",
        default="results",
        metavar="DIR",
        help="the results directory: results.db and the tables (default: %(default)s)",
    )
    p.add_argument(
        "--workers", type=int, default=os.cpu_count() or 1, help="worker processes (default: the core count)"
    )
    p.add_argument(
        "--backend",
        default="local",
        choices=["local", "ray"],
        help="local processes or Ray tasks (default: %(default)s)",
    )
    p.add_argument("--ray-address", default=None, help="Ray cluster address (default: start a local Ray)")
    p.add_argument(
        "--agent-opt",
        action="append",
        metavar="AGENT.KEY=VALUE",
        help="a guardian constructor argument (VALUE as JSON), e.g. hj.margin=0.3 or lrmm.threshold=0.9; repeatable",
    )
    p.add_argument(
        "--episode-timeout",
        type=float,
        default=600.0,
        help="wall seconds before an episode is stopped; it is stored as a failure that a rerun retries (default: %(default)s)",
    )
    p.add_argument(
        "--charge-precompute",
        action="store_true",
        help="charge a guardian's reset (e.g. an HJ solve) to the first step's clock",
    )
    p.add_argument(
        "--batch-size", type=int, default=64, help="episodes per batch for the rate statistics (default: %(default)s)"
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="finish an interrupted run: runs missing episodes and retries those over the time limit or lost with their worker "
        "(rerunning the same command does the same)",
    )
    p.add_argument(
        "--retry-errors",
        action="store_true",
        help="also run again the episodes stored as guardian errors (after fixing the guardian or its options)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--no-figure",
        action="store_true",
        help="write the tables, not the figure (one left from an earlier run is removed, as it would not match)",
    )
    return p


def run_parser(description: str | None = None) -> argparse.ArgumentParser:
    """``rmm-bench run`` (also ``rmm-bench`` with no subcommand); ``description``: the help's text
    (default: :mod:`rmm_bench.run_command`'s)."""
    if description is None:
        description = run_command.__doc__
    p = argparse.ArgumentParser(
        prog="rmm-bench run",
        description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[run_options("lrmm")],
    )
    p.add_argument(
        "--clock", default="wall", help="what a decision's compute time is: wall (default), cpu, or fixed:MS"
    )
    p.add_argument(
        "--shard",
        default=None,
        metavar="K/N",
        help="run only share K of N of the episodes (episode i when i mod N = K - 1; the same on every "
        "machine), to merge later with rmm-bench merge (docs/machines.md)",
    )
    return p


def sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench sweep",
        description="Collision rate against added decision latency (fixed-latency clock), or, with a --disturb "
        "item of several levels (e.g. --disturb obs-noise.rays=0.1,0.3,1.0), every rate against that disturbance's "
        "level, paired with the undisturbed episodes (at one latency, 1 ms unless --latency gives another).",
        parents=[run_options("lrmm,cbf")],
    )
    p.add_argument(
        "--latency",
        default=None,
        help="comma list of decision latencies in ms (default: 0,1,5,20,50; one value, 1, when a disturbance is swept)",
    )
    p.set_defaults(episodes=256)
    return p


def _check_counts(args) -> None:
    """Options that need nothing imported."""
    if args.episodes < 1:
        raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    if args.batch_size < 1:
        raise ValueError(f"--batch-size must be >= 1, got {args.batch_size}")
    if args.seed < 0:
        raise ValueError(f"--seed must be a non-negative integer, got {args.seed}")
    if not (math.isfinite(args.episode_timeout) and args.episode_timeout > 0):
        raise ValueError(
            f"--episode-timeout must be a positive, finite number of seconds, got {args.episode_timeout:g}"
        )


def _config(args, clock: str, latencies: tuple[float, ...] = ()) -> BenchConfig:
    classes = resolve_agents(args.agent)
    agents = list(classes)
    agent_kwargs = parse_agent_opts(args.agent_opt or [], agents)
    env_id = args.env
    takes = env_arguments(env_id)  # ValueError if not registered; the contract is checked when the env is built
    if args.base_step is None:  # the env's own default (stored as given, so the run's identity names it)
        args.base_step = env_default(env_id, "base_step", NON_BLOCKING_DEFAULTS["base_step"])
    options = {"time_accel": args.time_accel, "base_step": args.base_step, "clock": clock}
    env_opts = parse_env_opts(args.env_opt, env_parameters(env_id), env_id)
    dist = disturbance_opts(getattr(args, "disturb", None), env_opts, env_parameters(env_id), env_id)
    env_opts = {k: v for k, v in env_opts.items() if k != "disturbances"} | dist
    for name in ENV_OPTIONS:
        if name in env_opts:  # the command's own flag sets it, and the run's identity names it there
            flag = "--clock" if name == "clock" else "--" + name.replace("_", "-")
            raise ValueError(f"--env-opt {name}=...: set it with {flag}, the command's own flag for it")
    for name, default in NON_BLOCKING_DEFAULTS.items():
        if name not in takes and options[name] != default:  # a blocking env would silently ignore it
            flag = "--" + name.replace("_", "-")
            raise ValueError(
                f"{flag} {options[name]:g}: {env_id} steps by a fixed step per decision and takes no "
                f"{name}; leave {flag} out, or run its non-blocking (Parallel) twin"
            )
    return BenchConfig(
        agents=tuple(agents),
        agent_kwargs=agent_kwargs,
        env_id=env_id,
        agent_classes=classes,
        env_kwargs=env_opts | {k: v for k, v in options.items() if k in takes},
        clock=clock,
        seed=args.seed,
        episodes=args.episodes,
        out=args.out,
        workers=args.workers,
        backend=args.backend,
        ray_address=args.ray_address,
        episode_timeout=args.episode_timeout,
        charge_precompute=args.charge_precompute,
        batch_size=args.batch_size,
        retry_errors=args.retry_errors,
        progress=not args.no_progress,
        figure=not args.no_figure,
        parsed={k: v for k, v in vars(args).items() if k not in ("env_opt", "disturb") or v},  # unset: as stored before
        latencies=latencies,
        agent_set=args.agent.strip() if guardian_set(args.agent) is not None else None,
        shard=None if getattr(args, "shard", None) is None else parse_shard(args.shard),
    )


def parse_run(argv: list[str], description: str | None = None) -> BenchConfig:
    args = run_parser(description).parse_args(argv)
    _check_counts(args)
    try:
        make_clock(args.clock)
    except ValueError as e:
        raise ValueError(f"--clock {args.clock}: {e}") from None
    args.shard = None if args.shard is None else "/".join(map(str, parse_shard(args.shard)))
    return _config(args, args.clock)


def parse_sweep(argv: list[str], disturbance_swept: bool = False) -> BenchConfig:
    """A sweep's config carries its latencies and the first one's clock; the command derives
    one config per latency with :meth:`BenchConfig.with_clock`.  A disturbance sweep runs at one
    latency (``--latency``, default 1 ms)."""
    args = sweep_parser().parse_args(argv)
    _check_counts(args)
    text = args.latency if args.latency is not None else ("1" if disturbance_swept else "0,1,5,20,50")
    try:
        latencies = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        latencies = ()
    if not latencies or any(not 0 <= x < float("inf") for x in latencies):
        raise ValueError(f"--latency must be a comma list of non-negative milliseconds, got {text!r}")
    if disturbance_swept and len(latencies) > 1:
        raise ValueError(f"--latency {text}: a disturbance sweep runs at one latency; sweep one thing at a time")
    return _config(args, f"fixed:{latencies[0]:g}", latencies)


def run_cmd(argv: list[str]) -> int:
    """``rmm-bench run`` (and ``rmm-bench`` with no subcommand); ``argv`` is recorded with the run."""
    return cmd_run(parse_run(argv), argv)


def sweep_cmd(argv: list[str]) -> int:
    """``rmm-bench sweep``: over latencies, or over a disturbance's levels (:mod:`rmm_bench.disturb_sweep`)."""
    rest, swept = split_swept(argv)
    if swept is not None:
        return cmd_disturbance_sweep(parse_sweep(rest, disturbance_swept=True), swept, ["sweep", *argv])
    return cmd_sweep(parse_sweep(argv), ["sweep", *argv])
