"""``rmm-bench reproduce``: the command line of :mod:`rmm_bench.reproduce`'s checks.

``--list`` marks the manifests that are clone only: those whose commands run one of the
repository's development scripts (``python -m benchmarks.*``, timings above all), which a wheel
does not install; their other commands, and their quick versions, run from an install.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from rmm_bench.manifest import Manifest, clone_only, in_clone, load_manifests
from rmm_bench.reproduce import check_full, check_quick, expected_rates, update
from rmm_bench.reproduce_docs import write_docs

__all__ = ["build_parser", "cmd"]


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench reproduce`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench reproduce",
        description="Rerun the commands behind the published tables (manifests in rmm_bench/manifests) and "
        "check their numbers: --quick reruns small fixed-clock versions (or small datasets) that must match "
        "stored fingerprints bit for bit; without it the whole commands run, each published rate must lie in "
        "the 95% interval of the rate measured and each published speed ratio within its stated factor. "
        "Manifests of training runs and absolute timings are listed as not rerun.",
    )
    p.add_argument("names", nargs="*", metavar="NAME", help="manifests to run (default: all); --list names them")
    p.add_argument("--quick", action="store_true", help="the small fixed-clock versions (seconds to minutes)")
    p.add_argument("--check", action="store_true", help="compare with the stored fingerprints or rates")
    p.add_argument("--update", action="store_true", help="store the quick versions' fingerprints (maintainers)")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="the directory the runs go into (default: a temporary one)",
    )
    p.add_argument(
        "--list", action="store_true", help="list the manifests, what they cover, and those that need a clone"
    )
    p.add_argument("--write-docs", type=Path, default=None, metavar="PAGE", help="regenerate PAGE's tables")
    return p


def list_manifests(manifests: list[Manifest], clone: bool) -> int:
    """``--list``: each manifest, what it covers and, from a clone, the development scripts it
    runs; from a wheel, only the manifests whose commands run here, and one line naming the rest."""
    left_out = []
    for m in manifests:
        scripts = clone_only(m)
        if scripts and not clone:
            left_out.append(m.name)
            continue
        print(
            f"{m.name}: {m.title} ({len(expected_rates(m))} checked rates, {len(m.ratios)} checked "
            f"ratios, {len(m.fingerprints)} quick fingerprints)"
            + (f"; clone only: {', '.join(scripts)} (the repository's benchmarks/ scripts)" if scripts else "")
        )
    if left_out:
        print(
            f"not listed: {', '.join(left_out)}: their commands run the repository's benchmarks/ scripts, "
            "which this install does not have (check them from a clone)"
        )
    return 0


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench reproduce``: 0 when everything checked reproduces, 1 when a number differs."""
    args = build_parser().parse_args(argv)
    manifests = load_manifests(args.names or None)
    if args.list:
        return list_manifests(manifests, in_clone())
    if args.write_docs is not None:
        changed = write_docs(args.write_docs)
        print(f"{args.write_docs}: {'regenerated' if changed else 'current'}")
        return 0
    if args.update and not args.quick:
        raise ValueError("--update stores the quick versions' fingerprints: use it with --quick")
    problems: list[str] = []
    unchecked: list[str] = []
    with tempfile.TemporaryDirectory(prefix="rmm-reproduce-") as tmp:
        root = args.out or Path(tmp)
        for m in manifests:
            if not _checkable(m, args.quick):
                why = "no quick version" if args.quick else "no rmm-bench runs of rated agents and no ratios"
                unchecked.append(m.name)
                print(f"{m.name}: not rerun ({why}; run its commands as printed in the docs to check it)")
                continue
            out = root / (m.name + ("-quick" if args.quick else ""))
            if (out / "results.db").exists() and args.out is not None and args.quick:
                (out / "results.db").unlink()
            print(
                f"{m.name}: running {'the quick version' if args.quick else 'the whole commands'} into {out}",
                file=sys.stderr,
            )
            if args.update:
                update(m, out)
                print(f"{m.name}: fingerprints stored in {m.path.name}")
                continue
            try:
                found = check_quick(m, out) if args.quick else check_full(m, out)
            except RuntimeError as e:  # a command that failed: the other manifests still run
                found = [f"{m.name}: {e}"]
            if args.check:
                problems += found
                print(f"{m.name}: {'reproduced' if not found else 'DIFFERS'}")
    for line in problems:
        print(line)
    if args.check:
        rerun = len(manifests) - len(unchecked)
        print(
            f"{rerun - len({p.split(':')[0] for p in problems})} of {rerun} manifests reproduced"
            + (f"; {len(unchecked)} not rerun ({', '.join(unchecked)})" if unchecked else "")
        )
    return 1 if problems else 0


def _checkable(m: Manifest, quick: bool) -> bool:
    """Whether ``reproduce`` can rerun ``m`` (its quick version, or its whole commands and rates)."""
    if quick:
        return bool(m.quick_commands or m.quick_datagen)
    rerun = bool(m.commands) or bool(m.check.get("commands")) or bool(m.check.get("columns"))
    return (rerun and (m.kind != "table" or bool(m.check))) or bool(m.ratios)


if __name__ == "__main__":
    sys.exit(cmd(sys.argv[1:]))
