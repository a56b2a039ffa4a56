"""``rmm-bench model-spread``: how much ``lrmm``'s Table I rates move between models trained under other seeds.

    rmm-bench model-spread --env Dubins3DMazeParallel-v0 --episodes 256 \\
        --models results/spread/maze_seed0.npz,results/spread/maze_seed1.npz,... --out results/spread

Each model (trained on the same data with ``rmm-train --seed S``) gets the decision the guardian
reads for ``--env`` with the shipped model (its threshold and strategies, written beside a copy of
the file with :func:`rmm_guardians.lrmm.decision.set_decision`, so only the weights differ), then runs the
same episodes (``--seed``, fixed 1 ms clock) as ``lrmm``.  Prints each model's success,
collision and timeout rates and intervention share, their mean and range over the models, and
the shipped model's row on the same episodes; writes the table to ``--out``/``spread_<env>.md``.
"""

from __future__ import annotations

import argparse
import json
import shlex
import shutil
import statistics
import sys
from pathlib import Path

from rmm_bench.knob_sweep import run_point
from rmm_bench.manifest import MANIFESTS, table_manifest
from rmm_guardians.lrmm.decision import set_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.strategies import strategy_specs

__all__ = ["build_parser", "cmd"]

COLUMNS = (("success", "Success [%]"), ("collision", "Collision [%]"), ("timeout", "Timeout [%]"))


def _decided_copy(model: Path, env_id: str, out: Path) -> Path:
    """A copy of ``model`` in ``out`` with the decision of ``env_id``'s shipped guardian beside it."""

    shipped = LRMMGuardian(env_id=env_id)
    copy = out / f"{model.stem}_decided.npz"
    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(model, copy)
    specs = ", ".join(strategy_specs(shipped.strategies))
    set_decision(copy, shipped.threshold, specs, f"copied from the guardian shipped for {env_id} (model_spread)")
    return copy


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench model-spread`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench model-spread",
        description="How much lrmm's rates move between models trained on the same data under other seeds: each "
        "model gets the decision of the env's shipped guardian (only the weights differ) and runs the same episodes "
        "under a fixed 1 ms clock, beside the shipped model.",
    )
    p.add_argument("--env", required=True, help="the env of every run (one rmm-bench runs)")
    p.add_argument("--models", required=True, help="comma-separated model files (one per training seed)")
    p.add_argument("--episodes", type=int, default=256, help="episodes of every run (default: %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="master seed; episode i's seed derives from it (default: %(default)s)"
    )
    p.add_argument("--workers", type=int, default=None, help="worker processes of each run (default: rmm-bench's)")
    p.add_argument(
        "--out",
        default="results/spread",
        metavar="DIR",
        help="the directory of the runs and the table (default: %(default)s)",
    )
    p.add_argument("--manifest", metavar="NAME", help="also write the table as manifest NAME (rmm_bench/manifests)")
    p.add_argument("--made-by", action="append", default=[], help="with --manifest: a command that made the models")
    return p


def cmd(argv: list[str]) -> int:
    """``rmm-bench model-spread ARGS``: the exit status (2: bad input, one line)."""
    args = build_parser().parse_args(argv)
    models = [Path(m.strip()) for m in args.models.split(",") if m.strip()]
    missing = [str(m) for m in models if not m.is_file()]
    if len(models) < 2 or missing or args.episodes < 1:
        why = f"model files {missing} do not exist" if missing else "--models needs two or more files"
        print(
            f"rmm-bench model-spread: error: {why if len(models) < 2 or missing else '--episodes must be >= 1'}",
            file=sys.stderr,
        )
        return 2
    out = Path(args.out) / f"{args.env}_seed{args.seed}"
    rows = []
    for m in models:
        try:
            decided = _decided_copy(m, args.env, out / "models")
        except ValueError as e:
            print(f"rmm-bench model-spread: error: {m}: {e}", file=sys.stderr)
            return 2
        opt = f"lrmm.model={json.dumps(str(decided.resolve()))}"
        rows.append(
            (
                m.name,
                run_point("lrmm", [opt], out / m.stem, args.episodes, args.seed, "fixed:1", args.workers, args.env),
            )
        )
    shipped = run_point("lrmm", [], out / "shipped", args.episodes, args.seed, "fixed:1", args.workers, args.env)
    command = "rmm-bench model-spread " + " ".join(shlex.quote(a) for a in argv)
    header = ["model", *(h for _, h in COLUMNS), "Intervention [% sim time]"]
    table = [
        [name, *(f"{r[f'{k}_mean']:.1f}" for k, _ in COLUMNS), f"{r['intervention_mean']:.1f}"]
        for name, r in rows + [("shipped model", shipped)]
    ]
    stats = []
    for k in [k for k, _ in COLUMNS] + ["intervention"]:
        v = [r[f"{k}_mean"] for _, r in rows]
        stats.append(f"{statistics.fmean(v):.1f} ({min(v):.1f}–{max(v):.1f})")
    table.append([f"mean (range) of the {len(rows)} seeds", *stats])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + [
        "| " + " | ".join(c) + " |" for c in table
    ]
    text = f"{args.env}, {args.episodes} episodes of seed {args.seed}, fixed 1 ms clock\n\nCommand: `{command}`\n\n"
    text += "\n".join(lines) + "\n"
    (Path(args.out) / f"spread_{args.env}.md").write_text(text)
    print(text)
    if args.manifest:
        import datetime
        import os

        fields = {
            "name": args.manifest,
            "title": f"`lrmm` on `{args.env}` with models trained on the same data under {len(rows)} seeds, "
            f"{args.episodes} episodes of seed {args.seed}, fixed 1 ms clock",
            "section": "Is the map right? Calibration on held-out worlds",
            "commands": [*args.made_by, command.split(" --manifest")[0]],
            "measured": f"{datetime.date.today().isoformat()}, {os.cpu_count()} cores",
            "header": header,
            "rows": table,
        }
        path = MANIFESTS / f"{args.manifest}.toml"
        path.write_text(table_manifest(fields))
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(cmd(sys.argv[1:]))
