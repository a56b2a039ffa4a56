"""``rmm-bench compare``: the command line of :func:`rmm_bench.compare.compare_runs`."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rmm_bench.compare import compare_runs
from rmm_bench.options import agent_option, refuse, results_dir
from rmm_bench.outputs import check_output, write_output
from rmm_bench.store import results_database

__all__ = ["build_parser", "cmd"]


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench compare`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench compare",
        description="Compare agents pair by pair on the episodes they all ran (same world, seed, clock and "
        "start): rate differences with paired 95% intervals, the exact McNemar test on the discordant "
        "episodes and their numbers (for rmm-bench replay), the floor no agent lifts, and paired bootstrap "
        "intervals of the continuous columns.  Opens the databases read-only.",
        parents=[
            results_dir(several=True),
            agent_option(
                "one agent or a comma list, each NAME or NAME@KEY (KEY: a prefix of the run key); "
                "default: every stored one"
            ),
        ],
    )
    p.add_argument("--unpaired", action="store_true", help="compare every episode of each agent as independent samples")
    p.add_argument(
        "--reference",
        action="store_true",
        help="also compare with the shipped reference results of the same episodes (agents ref:NAME)",
    )
    p.add_argument("--format", default="md", help="md (default) or csv")
    p.add_argument(
        "--table", type=Path, default=None, metavar="FILE", help="write the table to this file (default: stdout)"
    )
    refuse(p, "--out", "write the table with --table FILE (--out is a directory in every command)")
    p.add_argument("--bootstrap-seed", type=int, default=0, help="seed of the paired bootstrap (default: %(default)s)")
    refuse(p, "--seed", "use --bootstrap-seed (--seed is the master seed of a run)")
    p.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples (default 2000)")
    p.add_argument("--show", type=int, default=5, help="discordant episode numbers shown per side (default 5)")
    return p


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench compare``; bad input raises ``ValueError`` (exit 2 through the CLI)."""
    args = build_parser().parse_args(argv)
    if args.format not in ("md", "csv"):
        raise ValueError(f"--format {args.format!r}: expected md or csv")
    agents = None
    if args.agent is not None:
        agents = [a.strip() for a in args.agent.split(",") if a.strip()]
        if not agents:
            raise ValueError(f"--agent {args.agent!r}: expected one agent name or a comma list of them")
    existed = args.table is not None and args.table.exists()
    if args.table is not None:  # before anything is read: never over a database it reads (or any other)
        check_output(args.table, "--table", reads=[results_database(d, "compare") for d in args.results_dirs])
    comparison = compare_runs(
        args.results_dirs,
        agents,
        unpaired=args.unpaired,
        reference=args.reference,
        seed=args.bootstrap_seed,
        resamples=args.resamples,
        show=args.show,
    )
    if comparison.left_out:  # said in one line, never dropped silently
        left = "; ".join(comparison.left_out)
        print(f"rmm-bench compare: note: left out, as no other agent ran their episodes: {left}", file=sys.stderr)
    text = comparison.to_markdown(args.show) if args.format == "md" else comparison.to_csv()
    if args.table is None:
        sys.stdout.write(text)
    else:
        write_output(args.table, lambda tmp: tmp.write_text(text), existed=existed)
        print(f"wrote {args.table}", file=sys.stderr)
    return 0
