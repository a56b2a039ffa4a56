"""``rmm-bench report`` and ``rmm-bench replay``: their parsers, and their validation into requests.

A bad value raises ValueError naming the flag and the value (``rmm_bench.cli.main`` turns it
into one line and exit status 2).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from rmm_bench.options import agent_option, results_dir
from rmm_bench.replay import ReplayRequest, cmd_replay
from rmm_bench.report import cmd_report

__all__ = [
    "ReportRequest",
    "parse_replay",
    "parse_report",
    "replay_cmd",
    "replay_parser",
    "report_cmd",
    "report_parser",
]


def report_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-bench report",
        description="Rebuild Table I and the figures from a results database.",
        parents=[results_dir()],
    )
    p.add_argument(
        "--invocation",
        type=int,
        action="append",
        default=None,
        help="which recorded run (default: every run recorded under the newest run's configuration: env, "
        "clock, time accel, base step, seed); repeat to merge several (one table per configuration)",
    )
    p.add_argument(
        "--batch-size", type=int, default=64, help="episodes per batch for the rate statistics (default: %(default)s)"
    )
    p.add_argument(
        "--html",
        nargs="?",
        const="",
        default=None,
        metavar="FILE",
        help="also write the results page: one self-contained HTML file (default FILE: DIR/results.html)",
    )
    return p


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
    html = None if args.html is None else (Path(args.html) if args.html else Path(args.results_dir) / "results.html")
    return ReportRequest(
        dir=Path(args.results_dir),
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
        parents=[
            results_dir(),
            agent_option("the stored agent whose run to replay, as the run named it (e.g. lrmm)", required=True),
        ],
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
    p.add_argument(
        "--frames",
        default=None,
        metavar="FOLDER",
        help="write one PNG per frame into this folder (FOLDER/epI for several)",
    )
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
        dir=Path(args.results_dir),
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


# ---------------------------------------------------------------- the commands (rmm_bench.cli's table)


def report_cmd(argv: list[str]) -> int:

    return cmd_report(parse_report(argv))


def replay_cmd(argv: list[str]) -> int:

    return cmd_replay(parse_replay(argv))
