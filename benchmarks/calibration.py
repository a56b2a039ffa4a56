"""Is the map right?  The shipped models' risk against fresh risk labels on held-out worlds.

Run: ``python -m benchmarks.calibration [--systems Dubins4D,Dubins3DMaze,...] [--seed 2026]
[--workers 2] [--out results/calibration]``.

For each system, ``rmm-datagen`` labels states of worlds drawn from ``--seed`` (the shipped
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

import numpy as np

__all__ = ["CALIBRATED", "calibrate", "main", "reliability"]

#: system (its catalog name, as in rmm_envs.catalog) -> the env whose labels the model learned,
#: the model ``lrmm`` reads, the labelling arguments of its training dataset (tree and sampler;
#: the driven envs' are their adapters' defaults), and how many worlds x states to label
CALIBRATED = {
    "Dubins4D": {
        "env": ["--env", "Dubins4DGuarded-v0"],
        "model": "dubins4d_act.npz",
        "size": ["--configs", "64", "--samples-per-config", "64"],
    },
    "Dubins3DMaze": {
        "env": ["--env", "Dubins3DMaze-v0", "--env-kwargs", '{"maze_kind": "mixed"}', "--configs-per-shard", "1"],
        "model": "dubins3d_maze.npz",
        "size": ["--configs", "4", "--samples-per-config", "512"],
    },
    "QuadrotorRoom": {
        "env": ["--env", "QuadrotorRoomGuarded-v0", "--branches", "16", "--depth", "2", "--horizon", "1.0"],
        "model": "quadrotor_cmd_act.npz",
        "size": ["--configs", "16", "--samples-per-config", "32", "--n-steps", "5"],
    },
    "CartPole": {
        "env": ["--env", "CartPoleGuarded-v0"],
        "model": "cartpole_guarded.npz",
        "size": ["--configs", "16", "--samples-per-config", "64"],
    },
    "InvertedPendulum": {
        "env": ["--env", "InvertedPendulumGuarded-v0"],
        "model": "inverted_pendulum_guarded.npz",
        "size": ["--configs", "16", "--samples-per-config", "64"],
    },
}
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


def calibrate(system: str, seed: int, workers: int, out: Path) -> dict:
    """Label held-out worlds of ``system`` into ``out/system`` and score the shipped model on them."""
    from rmm_envs.risk.datagen import main as datagen
    from rmm_envs.risk.dataset import load_dataset
    from rmm_guardians.lrmm.model import LRMMModel
    from rmm_guardians.lrmm.shipped import default_model_path

    spec = CALIBRATED[system]
    data = out / system
    args = [*spec["env"], *spec["size"], "--seed", str(seed), "--workers", str(workers), "--no-progress"]
    if datagen([*args, "--out", str(data)]) != 0:
        raise RuntimeError(f"rmm-datagen {' '.join(args)} failed")
    ds = load_dataset(data)
    model = LRMMModel.load(default_model_path().parent / spec["model"])
    pred = np.asarray(model.predict(ds.obs), float)
    label = np.asarray(ds.risk, float)
    brier = float(np.mean((pred - label) ** 2))
    constant = float(np.mean((label - label.mean()) ** 2))
    rows, ece = reliability(pred, label)
    return {
        "system": system,
        "model": spec["model"],
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


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--systems", default=",".join(CALIBRATED), help=f"comma list of {', '.join(CALIBRATED)}")
    p.add_argument("--seed", type=int, default=2026, help="the held-out worlds' seed (not 0 or 1: training's)")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=Path("results/calibration"))
    args = p.parse_args(argv)
    names = [s.strip() for s in args.systems.split(",") if s.strip()]
    unknown = [s for s in names if s not in CALIBRATED]
    if unknown or not names:
        p.error(
            f"--systems {args.systems!r}: unknown {unknown or 'none given'}, expected some of {', '.join(CALIBRATED)}"
        )
    if args.seed in (0, 1):
        p.error(f"--seed {args.seed}: the shipped models were trained on seeds 0 and 1; choose another")
    if args.out.exists() and any(args.out.iterdir()):
        p.error(f"--out {args.out} is not empty: the labels go into a fresh folder")
    args.out.mkdir(parents=True, exist_ok=True)
    results = [calibrate(s, args.seed, args.workers, args.out) for s in names]
    (args.out / "calibration.json").write_text(json.dumps(results, indent=1))
    md = _markdown(results)
    (args.out / "calibration.md").write_text(md)
    _figure(results, args.out / "reliability.png")
    print(md)
    print(f"wrote {args.out / 'calibration.md'}, calibration.json and reliability.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
