"""``rmm-bench`` command lines: the parsers, and their validation into a :class:`BenchConfig`.

Every option that needs no env or guardian built is checked here, once, and the result is a
frozen :class:`~rmm_bench.config.BenchConfig`; :func:`rmm_bench.checks.check_runs`
then builds the env and each guardian before any episode runs.  A bad value raises
ValueError naming the flag and the value (``main`` turns it into one line and exit status 2).
"""

from __future__ import annotations

import argparse
import math
import os
from dataclasses import dataclass
from pathlib import Path

from rmm_bench.config import BenchConfig
from rmm_envs.catalog import env_help
from rmm_envs.wrappers.nonblocking import BASE_STEP, TIME_ACCEL

__all__ = [
    "DEFAULT_ENV",
    "ReportRequest",
    "parse_replay",
    "parse_report",
    "parse_run",
    "parse_sweep",
    "replay_parser",
    "report_parser",
    "run_parser",
    "sweep_parser",
]

DEFAULT_ENV = "Dubins4DParallel-v0"
#: the non-blocking stepping options and their defaults (what a blocking env must be left with)
NON_BLOCKING_DEFAULTS = {"time_accel": TIME_ACCEL, "base_step": BASE_STEP}


def _common(p: argparse.ArgumentParser, default_agent: str) -> None:
    p.add_argument(
        "--agent",
        default=default_agent,
        help="guardian name, comma list, 'all' (defaults), 'paper' (the paper's rules), or module:Class (default: %(default)s)",
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
    p.add_argument("--out", default="results", help="output directory (default: %(default)s)")
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


def run_parser(description: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench", description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    _common(p, "lrmm")
    p.add_argument("--clock", default="wall", help="wall (default), cpu, or fixed:MS")
    p.add_argument(
        "--shard",
        default=None,
        metavar="K/N",
        help="run only share K of N of the episodes (episode i when i mod N = K - 1; the same on every "
        "machine), to merge later with rmm-bench merge (docs/machines.md)",
    )
    return p


def report_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench report", description="Rebuild Table I and the figures from a results database."
    )
    p.add_argument("dir", help="results directory holding results.db")
    p.add_argument(
        "--invocation",
        type=int,
        action="append",
        default=None,
        help="which recorded run (default: every run recorded under the newest run's configuration: env, "
        "clock, time accel, base step, seed); repeat to merge several (one table per configuration)",
    )
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument(
        "--html",
        nargs="?",
        const="",
        default=None,
        metavar="FILE",
        help="also write the results page: one self-contained HTML file (default FILE: DIR/results.html)",
    )
    return p


def sweep_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench sweep", description="Collision rate against added decision latency (fixed-latency clock)."
    )
    _common(p, "lrmm,cbf")
    p.add_argument(
        "--latency", default="0,1,5,20,50", help="comma list of decision latencies in ms (default: %(default)s)"
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
    from rmm_bench.checks import env_arguments, env_default, parse_agent_opts, resolve_agents
    from rmm_bench.config import parse_shard
    from rmm_guardians.registry import guardian_set

    classes = resolve_agents(args.agent)
    agents = list(classes)
    agent_kwargs = parse_agent_opts(args.agent_opt or [], agents)
    env_id = args.env
    takes = env_arguments(env_id)  # ValueError if not registered; the contract is checked when the env is built
    if args.base_step is None:  # the env's own default (stored as given, so the run's identity names it)
        args.base_step = env_default(env_id, "base_step", NON_BLOCKING_DEFAULTS["base_step"])
    options = {"time_accel": args.time_accel, "base_step": args.base_step, "clock": clock}
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
        env_kwargs={k: v for k, v in options.items() if k in takes},
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
        parsed=vars(args),
        latencies=latencies,
        agent_set=args.agent.strip() if guardian_set(args.agent) is not None else None,
        shard=None if getattr(args, "shard", None) is None else parse_shard(args.shard),
    )


def parse_run(argv: list[str], description: str) -> BenchConfig:
    args = run_parser(description).parse_args(argv)
    _check_counts(args)
    from rmm_envs.clocks import make_clock

    try:
        make_clock(args.clock)
    except ValueError as e:
        raise ValueError(f"--clock {args.clock}: {e}") from None
    from rmm_bench.config import parse_shard

    args.shard = None if args.shard is None else "/".join(map(str, parse_shard(args.shard)))
    return _config(args, args.clock)


def parse_sweep(argv: list[str]) -> BenchConfig:
    """A sweep's config carries its latencies and the first one's clock; the command derives
    one config per latency with :meth:`BenchConfig.with_clock`."""
    args = sweep_parser().parse_args(argv)
    _check_counts(args)
    try:
        latencies = tuple(float(x) for x in args.latency.split(",") if x.strip())
    except ValueError:
        latencies = ()
    if not latencies or any(not 0 <= x < float("inf") for x in latencies):
        raise ValueError(f"--latency must be a comma list of non-negative milliseconds, got {args.latency!r}")
    return _config(args, f"fixed:{latencies[0]:g}", latencies)


@dataclass(frozen=True)
class ReportRequest:
    """``rmm-bench report``: which directory, which recorded invocations (None: every run of the
    newest run's configuration, :func:`rmm_bench.report.newest_configuration`)."""

    dir: Path
    invocations: tuple[int, ...] | None
    batch_size: int
    html: Path | None = None  # the results page to write (None: none)


def parse_report(argv: list[str]) -> ReportRequest:
    args = report_parser().parse_args(argv)
    if args.batch_size < 1:
        raise ValueError(f"--batch-size must be >= 1, got {args.batch_size}")
    html = None if args.html is None else (Path(args.html) if args.html else Path(args.dir) / "results.html")
    return ReportRequest(
        dir=Path(args.dir),
        invocations=tuple(args.invocation) if args.invocation else None,
        batch_size=args.batch_size,
        html=html,
    )


def replay_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench replay",
        description="Re-simulate stored episodes exactly and verify them against their rows "
        "(prints 'verified' or the first differing column; exit 1 on a difference, 2 on bad input). "
        "The database is opened read-only.",
    )
    p.add_argument("dir", help="results directory holding results.db (a run's --out)")
    p.add_argument(
        "--agent", required=True, help="the stored agent whose run to replay, as the run named it (e.g. lrmm)"
    )
    p.add_argument("--episode", default=None, help="episode index, or a comma list (e.g. 3,17,40)")
    p.add_argument(
        "--where",
        default=None,
        help="an SQL condition on the agent's stored rows selecting episodes, e.g. \"outcome='collision'\"",
    )
    p.add_argument("--limit", type=int, default=None, help="replay at most this many of the selected episodes")
    p.add_argument(
        "--allow-errors",
        action="store_true",
        help="also replay episodes stored as errors, showing where the replay raised (a lost worker's cannot be)",
    )
    p.add_argument(
        "--trust-modules",
        action="store_true",
        help="import every module the database names (a module:Class agent, a module:Id env, a module:Name "
        "in the options, such as a strategy of one's own) without naming it here",
    )
    p.add_argument(
        "--trust-module",
        action="append",
        default=[],
        metavar="MODULE",
        help="import this module the database names (repeat, or a comma list), e.g. a strategy module of "
        'lrmm.strategies="+my_rules:Coast"',
    )
    p.add_argument(
        "--env",
        default=None,
        help="the run's env id; for a module:Id env, naming it here allows importing its module",
    )
    p.add_argument(
        "--invocation", type=int, default=None, help="replay the agent's run of this recorded command (default: newest)"
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--video",
        default=None,
        help="write the replayed episode as a video: FILE.mp4 (imageio-ffmpeg, the video extra) or FILE.gif "
        "(Pillow); several episodes write FILE-epI.mp4 each",
    )
    p.add_argument("--frames", default=None, help="write one PNG per frame into this folder (DIR/epI for several)")
    p.add_argument("--every", type=int, default=1, help="keep every K-th frame, and the last (default 1)")
    p.add_argument(
        "--fps", type=float, default=None, help="video frames per second (default: the episode's simulated pace)"
    )
    p.add_argument("--size", type=int, default=512, help="the picture's side in pixels (default 512; 64 to 2048)")
    return p


def _episode_list(text: str) -> tuple[int, ...]:
    try:
        out = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        out = ()
    if not out or any(i < 0 for i in out):
        raise ValueError(f"--episode {text!r}: expected an episode index >= 0 or a comma list of them, e.g. 3,17,40")
    return tuple(dict.fromkeys(out))


def _module_list(values: list[str]) -> tuple[str, ...]:
    out = tuple(m.strip() for v in values for m in v.split(",") if m.strip())
    for m in out:
        if not all(part.isidentifier() for part in m.split(".")):
            raise ValueError(f"--trust-module {m!r}: expected a module name (dotted Python identifiers, e.g. my_rules)")
    return out


def parse_replay(argv: list[str]):
    """``rmm-bench replay``'s arguments as a :class:`rmm_bench.replay.ReplayRequest`."""
    from rmm_bench.replay import ReplayRequest

    args = replay_parser().parse_args(argv)
    if args.episode is None and args.where is None:
        raise ValueError("replay: no episode chosen; expected --episode I (or a comma list) or --where CONDITION")
    if args.limit is not None and args.limit < 1:
        raise ValueError(f"--limit must be >= 1, got {args.limit}")
    if args.every < 1:
        raise ValueError(f"--every must be an integer >= 1, got {args.every}")
    if not 64 <= args.size <= 2048:
        raise ValueError(f"--size must be an integer from 64 to 2048 pixels, got {args.size}")
    if args.fps is not None and not 0 < args.fps <= 240:
        raise ValueError(f"--fps must be in (0, 240], got {args.fps}")
    return ReplayRequest(
        dir=Path(args.dir),
        agent=args.agent.strip(),
        episodes=None if args.episode is None else _episode_list(args.episode),
        where=args.where,
        limit=args.limit,
        allow_errors=args.allow_errors,
        trust_modules=args.trust_modules,
        trusted=_module_list(args.trust_module),
        env=args.env,
        invocation=args.invocation,
        progress=not args.no_progress,
        video=None if args.video is None else Path(args.video),
        frames=None if args.frames is None else Path(args.frames),
        every=args.every,
        fps=args.fps,
        size=args.size,
    )
