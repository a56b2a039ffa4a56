"""``rmm-bench calibrate``: is the map right?  A model's risk against fresh risk labels of held-out worlds.

Run: ``rmm-bench calibrate [--systems Dubins4D,Dubins3DMaze,...] [--world-seed 2026] [--workers 2]
[--out results/calibration]`` (the shipped models), or ``rmm-bench calibrate --env ENV --model
FILE`` (a model of one's own, on worlds of ``ENV`` labelled with ``rmm-datagen``'s defaults).

For each system, ``rmm-datagen`` labels states of worlds drawn from ``--world-seed`` (the shipped
models were trained on datasets of seeds 0 and 1, so these worlds are not theirs) with the
sampling tree the model was trained on, and the model the ``lrmm`` guardian reads predicts each
state's risk from its observation.  Reported per system:

* the **Brier score**: the mean squared difference between the predicted and the labelled risk
  (a label is the fraction of the tree's branches that crash, so this is the Brier score of a
  probabilistic target), next to that of the best constant (the fresh labels' own mean, an
  oracle no model can know; its Brier score is the labels' variance) and the skill score
  ``1 - Brier / Brier(constant)``;
* a **reliability table**: the predictions binned by tenths, per bin the number of states, the
  mean prediction and the mean label (a calibrated map has the two equal: a predicted 0.3 fails
  in about 30% of the branches), and the expected calibration error (the bins' mean absolute gap,
  weighted by their counts).

Writes ``calibration.md``, ``calibration.json`` and ``reliability.png`` under ``--out``.  Labels
and inference are the same bits on every machine for a seed, so the figures are too.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from rmm_bench.options import refuse
from rmm_envs.risk import datagen, dataset
from rmm_guardians.lrmm import model as lrmm_model
from rmm_guardians.lrmm.shipped import calibrated, models_dir

__all__ = ["CALIBRATED", "build_parser", "calibrate", "cmd", "main", "reliability"]

PROG = "rmm-bench calibrate"

#: system (its name in the table of systems) -> the env whose labels its shipped model learned
#: (with the labelling arguments of its training dataset), the model file and how many worlds x
#: states to label: each shipped model's ``calibration`` entry in ``shipped.toml``
CALIBRATED: dict[str, dict[str, Any]] = calibrated()
BINS = np.linspace(0.0, 1.0, 11)


def reliability(pred: np.ndarray, label: np.ndarray) -> tuple[list[dict], float]:
    """Per tenth of the predicted risk: ``{"bin", "n", "mean_pred", "mean_label"}`` (bins with
    states only), and the expected calibration error (count-weighted mean ``|pred - label|`` gap)."""
    pred, label = np.asarray(pred, float), np.asarray(label, float)
    idx = np.clip(np.searchsorted(BINS, pred, side="right") - 1, 0, len(BINS) - 2)
    rows, ece = [], 0.0
    for b in range(len(BINS) - 1):
        inside = idx == b
        n = int(inside.sum())
        if n:
            mp, ml = float(pred[inside].mean()), float(label[inside].mean())
            rows.append({"bin": f"{BINS[b]:.1f}-{BINS[b + 1]:.1f}", "n": n, "mean_pred": mp, "mean_label": ml})
            ece += n / pred.size * abs(mp - ml)
    return rows, ece


def calibrate(system: str, seed: int, workers: int, out: Path, spec: dict | None = None) -> dict:
    """Label held-out worlds of ``system`` into ``out/system`` and score its model on them: the
    shipped one (:data:`CALIBRATED`), or ``spec`` (``{"env": [...], "model": path, "size": [...]}``)."""
    spec = spec or CALIBRATED[system]
    data = out / system
    args = [*spec["env"], *spec["size"], "--seed", str(seed), "--workers", str(workers), "--no-progress"]
    if datagen.main([*args, "--out", str(data)]) != 0:
        raise RuntimeError(f"rmm-datagen {' '.join(args)} failed")
    ds = dataset.load_dataset(data)
    model = lrmm_model.LRMMModel.load(models_dir() / spec["model"])  # a path of one's own stays as given
    pred = np.asarray(model.predict(ds.obs), float)
    label = np.asarray(ds.risk, float)
    brier = float(np.mean((pred - label) ** 2))
    constant = float(np.mean((label - label.mean()) ** 2))
    rows, ece = reliability(pred, label)
    return {
        "system": system,
        "model": Path(spec["model"]).name,
        "labels": int(label.size),
        "worlds": int(np.unique(ds.config_id).size),
        "dataset_sha256": ds.sha256[:16],
        "command": "rmm-datagen " + " ".join(args),
        "brier": brier,
        "brier_constant": constant,
        "skill": 1.0 - brier / constant if constant > 0 else float("nan"),
        "ece": ece,
        "mean_label": float(label.mean()),
        "mean_pred": float(pred.mean()),
        "bins": rows,
    }


def _markdown(results: list[dict]) -> str:
    lines = [
        "| system | model | labels (worlds) | Brier | Brier of the labels' mean | skill | calibration error |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| {r['system']} | `{r['model']}` | {r['labels']:,} ({r['worlds']}) | {r['brier']:.4f} | "
            f"{r['brier_constant']:.4f} | {r['skill']:.2f} | {r['ece']:.3f} |"
        )
    for r in results:
        lines += ["", f"{r['system']}: predicted risk by tenths (states, mean prediction, mean label)", ""]
        lines += ["| bin | states | mean prediction | mean label |", "|---|---|---|---|"]
        lines += [f"| {b['bin']} | {b['n']} | {b['mean_pred']:.3f} | {b['mean_label']:.3f} |" for b in r["bins"]]
    return "\n".join(lines) + "\n"


def _figure(results: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cols = min(3, len(results))
    rows = -(-len(results) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4 * cols, 4 * rows), squeeze=False)
    for ax in axes.flat[len(results) :]:
        ax.set_visible(False)
    for ax, r in zip(axes.flat, results, strict=False):
        ax.plot([0, 1], [0, 1], color="0.6", lw=1, label="calibrated")
        xs = [b["mean_pred"] for b in r["bins"]]
        ys = [b["mean_label"] for b in r["bins"]]
        sizes = [20 + 200 * b["n"] / r["labels"] for b in r["bins"]]
        ax.scatter(xs, ys, s=sizes, color="tab:red", zorder=3, label="bins of tenths (area: states)")
        ax.plot(xs, ys, color="tab:red", lw=1)
        ax.set_title(f"{r['system']}: Brier {r['brier']:.3f}, ECE {r['ece']:.3f}")
        ax.set_xlabel("predicted risk")
        ax.set_ylabel("labelled risk (share of crashing branches)")
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Is the map right? A model's predicted risk against fresh risk labels of held-out worlds: "
        "Brier score, skill against the labels' mean, a reliability table and figure.",
    )
    p.add_argument("--systems", default=",".join(CALIBRATED), help=f"comma list of {', '.join(CALIBRATED)}")
    p.add_argument("--env", help="with --model: the env whose worlds label a model of your own (rmm-datagen --env)")
    p.add_argument(
        "--model", type=Path, help="with --env: a model of your own (rmm-train's) instead of the shipped ones"
    )
    p.add_argument("--configs", type=int, default=16, help="with --model: worlds to label (default: %(default)s)")
    p.add_argument(
        "--samples-per-config", type=int, default=64, help="with --model: states per world (default: %(default)s)"
    )
    p.add_argument(
        "--world-seed",
        type=int,
        default=2026,
        help="seed of the held-out worlds and their states (not the training data's; default: %(default)s)",
    )
    refuse(p, "--seed", "use --world-seed (--seed is the master seed of a run)")
    p.add_argument("--workers", type=int, default=2, help="labelling processes (default: %(default)s)")
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results/calibration"),
        metavar="DIR",
        help="a new or empty directory for the labels, the tables and the figure (default: %(default)s)",
    )
    return p


def _bad(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2


def _own(args) -> tuple[list[str], dict | None] | str:
    """The systems to score and, for a model of one's own, its spec; or what is wrong, in a line."""
    if args.model is None and args.env is None:
        names = [s.strip() for s in args.systems.split(",") if s.strip()]
        unknown = [s for s in names if s not in CALIBRATED]
        if unknown or not names:
            return f"--systems {args.systems!r}: unknown {unknown or 'none given'}, expected some of {', '.join(CALIBRATED)}"
        if args.world_seed in (0, 1):
            return f"--world-seed {args.world_seed}: the shipped models were trained on seeds 0 and 1; choose another"
        return names, None
    if args.model is None or args.env is None:
        return "--env and --model go together: the env whose worlds are labelled and the model scored on them"
    if args.configs < 1 or args.samples_per_config < 1:
        return "--configs and --samples-per-config must be >= 1"
    try:
        trained = lrmm_model.LRMMModel.load(args.model).meta.get("data", {}).get("seed")
    except (ValueError, FileNotFoundError) as e:
        return str(e)
    if trained == args.world_seed:
        return f"--world-seed {args.world_seed}: {args.model} was trained on worlds of that seed; choose another"
    size = ["--configs", str(args.configs), "--samples-per-config", str(args.samples_per_config)]
    return [args.model.stem], {"env": ["--env", args.env], "model": args.model.resolve(), "size": size}


def cmd(argv: list[str]) -> int:
    """``rmm-bench calibrate ARGS``: the exit status (2: bad input, one line)."""
    args = build_parser().parse_args(argv)
    what = _own(args)
    if isinstance(what, str):
        return _bad(what)
    names, spec = what
    if args.out.exists() and (not args.out.is_dir() or any(args.out.iterdir())):
        return _bad(f"--out {args.out} is not empty: the labels go into a fresh folder")
    args.out.mkdir(parents=True, exist_ok=True)
    results = [calibrate(s, args.world_seed, args.workers, args.out, spec) for s in names]
    (args.out / "calibration.json").write_text(json.dumps(results, indent=1))
    md = _markdown(results)
    (args.out / "calibration.md").write_text(md)
    print(md)
    try:
        _figure(results, args.out / "reliability.png")
    except ImportError:  # matplotlib is optional: the tables are the result
        print(f"wrote {args.out / 'calibration.md'} and calibration.json (no figure: matplotlib is not installed)")
        return 0
    print(f"wrote {args.out / 'calibration.md'}, calibration.json and reliability.png")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m rmm_bench.calibration``: :func:`cmd` of the command line."""
    return cmd(list(sys.argv[1:] if argv is None else argv))


if __name__ == "__main__":
    sys.exit(main())
