"""``rmm-bench knob-sweep``: collision rate against intervention rate across one guardian's main knob.

A guardian's safety can always be bought with interventions (brakes-only never lets the driver
drive); the honest picture of a rule is the curve it traces as its main knob moves, with the
default marked.  This command runs ``rmm-bench`` once per knob value, under a fixed decision
clock (so the runs are bit-reproducible and independent of machine load), and writes a
Markdown table and a figure::

    rmm-bench knob-sweep --agent lrmm --knob threshold --values 0.1,0.2,0.3,0.5,0.85 \\
        --default 0.3 --episodes 256 --out results/knobs

Outputs, under ``--out``: ``<agent>_<knob>.md`` (success, collision, timeout and intervention
rates per value, mean ± std over batches of 64 as in Table I), ``<agent>_<knob>.png``
(collision rate against intervention rate, one point per value, the default starred, the
driver alone as a reference) and one ``rmm-bench`` result directory per value (rerunning the
command resumes them).  ``rmm-bench tune`` uses the same runs to choose and write ``lrmm``'s
decision for a model (:mod:`rmm_bench.tune`).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
from pathlib import Path

from rmm_bench import cli
from rmm_bench.options import refuse

__all__ = ["bench_argv", "build_parser", "cmd", "main", "read_row", "run_bench", "run_point"]

PROG = "rmm-bench knob-sweep"


def read_row(out: Path, agent: str) -> dict:
    """``agent``'s Table I row of the run in ``out`` (its ``table_I.csv``), numbers as floats."""
    with open(out / "table_I.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["agent"] == agent:
                return {k: (float(v) if k not in ("agent", "observation", "rate_spread") else v) for k, v in r.items()}
    raise RuntimeError(f"{out / 'table_I.csv'} has no row for agent {agent!r}")


def bench_argv(
    agent: str,
    opts: list[str],
    out: Path,
    episodes: int,
    seed: int,
    clock: str,
    workers: int | None,
    env: str | None = None,
) -> list[str]:
    """The ``rmm-bench`` arguments of one run of ``agent`` with the ``--agent-opt`` values ``opts``."""
    argv = ["--agent", agent, "--episodes", str(episodes), "--seed", str(seed), "--clock", clock]
    argv += ["--out", str(out), "--no-progress"]
    for o in opts:
        argv += ["--agent-opt", o]
    if workers:
        argv += ["--workers", str(workers)]
    if env:
        argv += ["--env", env]
    return argv


def run_bench(argv: list[str]) -> int:
    """Run ``rmm-bench argv`` in this process, its table kept off stdout (errors still go to stderr)."""
    with contextlib.redirect_stdout(io.StringIO()):  # each run prints its table; the caller prints its own
        return cli.main(argv)


def run_point(
    agent: str,
    opts: list[str],
    out: Path,
    episodes: int,
    seed: int,
    clock: str,
    workers: int | None,
    env: str | None = None,
) -> dict:
    """Run ``rmm-bench`` for one agent and options (on ``env``, default the default env); return
    its Table I row (from table_I.csv)."""
    argv = bench_argv(agent, opts, out, episodes, seed, clock, workers, env)
    rc = run_bench(argv)
    if rc:
        raise SystemExit(f"rmm-bench {' '.join(argv)} exited with {rc}")
    return read_row(out, agent)


def _label(v) -> str:
    return json.dumps(v) if not isinstance(v, str) else v


def plot(points: list[tuple[str, dict]], default: str | None, reference: dict | None, title: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.0), dpi=120)
    xs = [p["intervention_mean"] for _, p in points]
    ys = [p["collision_mean"] for _, p in points]
    ax.plot(xs, ys, "-o", color="tab:blue", ms=4, lw=1)
    for v, p in points:
        ax.annotate(
            v, (p["intervention_mean"], p["collision_mean"]), textcoords="offset points", xytext=(4, 4), fontsize=7
        )
        if v == default:
            ax.plot(
                [p["intervention_mean"]], [p["collision_mean"]], "*", color="tab:red", ms=14, label=f"default ({v})"
            )
    if reference is not None:
        ax.plot(
            [reference["intervention_mean"]],
            [reference["collision_mean"]],
            "s",
            color="grey",
            ms=6,
            label="driver alone",
        )
    ax.set_xlim(left=-1)  # the driver alone sits at 0
    ax.set_ylim(bottom=0)
    ax.set_xlabel("intervention [% sim time]")
    ax.set_ylabel("collision rate [% episodes]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Collision rate against intervention rate across one guardian's main knob: one rmm-bench run "
        "per value under a fixed clock, a table and a figure.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--agent", required=True, help="the one guardian whose knob to sweep (e.g. lrmm, hj, cbf)")
    refuse(p, "--agents", "use --agent (one guardian)")
    p.add_argument("--knob", required=True, help="the constructor argument to sweep (e.g. threshold)")
    p.add_argument("--values", required=True, help="comma-separated values, each parsed as JSON")
    p.add_argument("--default", default=None, help="the guardian's default value of the knob (marked in the figure)")
    p.add_argument(
        "--agent-opt",
        action="append",
        default=[],
        metavar="AGENT.KEY=VALUE",
        help="fixed options passed to every run (repeatable)",
    )
    p.add_argument("--env", default=None, help="the env of every run (default: rmm-bench's)")
    p.add_argument("--episodes", type=int, default=256, help="episodes of every run (default: %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="master seed; episode i's seed derives from it (default: %(default)s)"
    )
    p.add_argument("--clock", default="fixed:1", help="decision clock of every run (default fixed:1, reproducible)")
    p.add_argument("--workers", type=int, default=None, help="worker processes of each run (default: rmm-bench's)")
    p.add_argument("--no-reference", action="store_true", help="do not run the driver alone as a reference point")
    p.add_argument(
        "--out",
        default="results/knobs",
        metavar="DIR",
        help="the directory of the runs, the table and the figure (default: %(default)s)",
    )
    return p


def cmd(argv: list[str]) -> int:
    """``rmm-bench knob-sweep ARGS``: the exit status (2: bad input, one line)."""
    args = build_parser().parse_args(argv)
    if args.episodes < 1:
        print(f"{PROG}: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    try:
        values = [json.loads(v) for v in args.values.split(",") if v.strip()]
    except json.JSONDecodeError as e:
        print(
            f"{PROG}: error: --values must be comma-separated JSON values, got {args.values!r} ({e})", file=sys.stderr
        )
        return 2
    if not values:
        print(f"{PROG}: error: --values is empty", file=sys.stderr)
        return 2
    default = None
    if args.default is not None:
        try:
            default = json.loads(args.default)
        except json.JSONDecodeError:
            default = args.default  # a bare string value
        # the label of the swept value equal to the default (1 and 1.0 are the same knob value)
        default = next((_label(v) for v in values if v == default), _label(default))
    out = Path(args.out)
    tag = f"{args.agent.replace(':', '_')}_{args.knob}"
    runs = [
        (_label(v), args.agent, list(args.agent_opt) + [f"{args.agent}.{args.knob}={json.dumps(v)}"]) for v in values
    ] + ([] if args.no_reference else [("inactive", "inactive", [])])
    measured: dict[str | None, dict] = {}  # label -> row; None: the driver alone
    for label, agent, opts in runs:
        folder = out / tag / (f"{args.knob}={label}" if agent == args.agent else "inactive")
        rc = run_bench(bench_argv(agent, opts, folder, args.episodes, args.seed, args.clock, args.workers, args.env))
        if rc:  # rmm-bench said why in one line
            return rc
        measured[label if agent == args.agent else None] = read_row(folder, agent)
    reference = measured.pop(None, None)
    points = [(str(label), row) for label, row in measured.items()]
    command = f"{PROG} " + " ".join(argv)
    lines = [
        f"{args.agent}: {args.knob} sweep, {args.episodes} episodes, seed {args.seed}, clock {args.clock}",
        "",
        f"Command: `{command}`",
        "",
        f"| {args.knob} | Success [%] | Collision [%] | Timeout [%] | Intervention [% sim time] |",
        "|---|---|---|---|---|",
    ]
    for v, p in points + ([("driver alone (inactive)", reference)] if reference else []):
        mark = " (default)" if v == default else ""
        lines.append(
            f"| {v}{mark} | {p['success_mean']:.1f} ± {p['success_std']:.1f} | {p['collision_mean']:.1f} ± "
            f"{p['collision_std']:.1f} | {p['timeout_mean']:.1f} ± {p['timeout_std']:.1f} | "
            f"{p['intervention_mean']:.1f} ± {p['intervention_std']:.1f} |"
        )
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{tag}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    try:
        plot(
            points,
            default,
            reference,
            f"{args.agent}: collisions vs interventions across {args.knob}",
            out / f"{tag}.png",
        )
    except ImportError:  # matplotlib is optional: the table is the result
        print(f"wrote {out / (tag + '.md')} (no figure: matplotlib is not installed)")
        return 0
    print(f"wrote {out / (tag + '.md')} and {out / (tag + '.png')}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m rmm_bench.knob_sweep``: :func:`cmd` of the command line."""
    return cmd(list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
