"""Collision rate against intervention rate across one guardian's main knob.

A guardian's safety can always be bought with interventions (brakes-only never lets the driver
drive); the honest picture of a rule is the curve it traces as its main knob moves, with the
default marked.  This script runs ``rmm-bench`` once per knob value, under a fixed decision
clock (so the runs are bit-reproducible and independent of machine load), and writes a
Markdown table and a figure::

    python -m benchmarks.knob_sweep --agent lrmm --knob threshold --values 0.1,0.2,0.3,0.5,0.85 \\
        --default 0.3 --episodes 256 --out results/knobs

Outputs, under ``--out``: ``<agent>_<knob>.md`` (success, collision, timeout and intervention
rates per value, mean ± std over batches of 64 as in Table I), ``<agent>_<knob>.png``
(collision rate against intervention rate, one point per value, the default starred, the
driver alone as a reference) and one ``rmm-bench`` result directory per value (rerunning the
command resumes them).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import json
import sys
from pathlib import Path

__all__ = ["main", "run_point"]


def _row(out: Path, agent: str) -> dict:
    with open(out / "table_I.csv", newline="") as f:
        for r in csv.DictReader(f):
            if r["agent"] == agent:
                return {k: (float(v) if k not in ("agent", "observation", "rate_spread") else v) for k, v in r.items()}
    raise RuntimeError(f"{out / 'table_I.csv'} has no row for agent {agent!r}")


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
    from rmm_bench.cli import main as bench

    argv = [
        "--agent",
        agent,
        "--episodes",
        str(episodes),
        "--seed",
        str(seed),
        "--clock",
        clock,
        "--out",
        str(out),
        "--no-progress",
    ]
    for o in opts:
        argv += ["--agent-opt", o]
    if workers:
        argv += ["--workers", str(workers)]
    if env:
        argv += ["--env", env]
    with contextlib.redirect_stdout(io.StringIO()):  # each run prints its table; the sweep prints its own
        rc = bench(argv)
    if rc:
        raise SystemExit(f"rmm-bench {' '.join(argv)} exited with {rc}")
    return _row(out, agent)


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
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--agent", required=True, help="guardian name (e.g. lrmm, hj, cbf)")
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
    p.add_argument("--episodes", type=int, default=256)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--clock", default="fixed:1", help="decision clock of every run (default fixed:1, reproducible)")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--no-reference", action="store_true", help="do not run the driver alone as a reference point")
    p.add_argument("--out", default="results/knobs")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.episodes < 1:
        print(f"knob_sweep: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    try:
        values = [json.loads(v) for v in args.values.split(",") if v.strip()]
    except json.JSONDecodeError as e:
        print(f"knob_sweep: --values must be comma-separated JSON values, got {args.values!r} ({e})", file=sys.stderr)
        return 2
    if not values:
        print("knob_sweep: --values is empty", file=sys.stderr)
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
    points = []
    for v in values:
        opts = list(args.agent_opt) + [f"{args.agent}.{args.knob}={json.dumps(v)}"]
        row = run_point(
            args.agent, opts, out / tag / f"{args.knob}={_label(v)}", args.episodes, args.seed, args.clock, args.workers
        )
        points.append((_label(v), row))
    reference = (
        None
        if args.no_reference
        else run_point("inactive", [], out / tag / "inactive", args.episodes, args.seed, args.clock, args.workers)
    )
    cmd = "python -m benchmarks.knob_sweep " + " ".join(argv if argv is not None else sys.argv[1:])
    lines = [
        f"{args.agent}: {args.knob} sweep, {args.episodes} episodes, seed {args.seed}, clock {args.clock}",
        "",
        f"Command: `{cmd}`",
        "",
        f"| {args.knob} | Success [%] | Collision [%] | Timeout [%] | Intervention [% sim time] |",
        "|---|---|---|---|---|",
    ]
    rows = points + ([("driver alone (inactive)", reference)] if reference else [])
    for v, p in rows:
        mark = " (default)" if v == default else ""
        lines.append(
            f"| {v}{mark} | {p['success_mean']:.1f} ± {p['success_std']:.1f} | {p['collision_mean']:.1f} ± "
            f"{p['collision_std']:.1f} | {p['timeout_mean']:.1f} ± {p['timeout_std']:.1f} | "
            f"{p['intervention_mean']:.1f} ± {p['intervention_std']:.1f} |"
        )
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{tag}.md").write_text("\n".join(lines) + "\n")
    plot(
        points, default, reference, f"{args.agent}: collisions vs interventions across {args.knob}", out / f"{tag}.png"
    )
    print("\n".join(lines))
    print(f"wrote {out / (tag + '.md')} and {out / (tag + '.png')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
