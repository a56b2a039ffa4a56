"""Training a learned risk metric map (``rmm-train``), with torch on the CPU.

``rmm-train --data data/d4 --out model.npz`` trains the paper's network by default:
``Linear(17, 64) -> sigmoid -> Linear(64, 1, no bias) -> sigmoid``, MSE loss, Adam (lr 1e-3),
batch 64, float64, on the dataset written by ``rmm-datagen``.  Splits are by obstacle
configuration (test metrics on layouts the model never saw); the scaler is fitted on the
training split only; the epoch is chosen on validation MSE (``--select``); the same data,
arguments and ``--seed`` give the same model bit for bit; with ``candidate_risk`` labels an
action-conditioned head is trained too (``--head``).  A NaN or inf loss stops training with a
message naming the epoch, and no model is written.  The guardian's decision defaults are
chosen after training, on development episodes: ``rmm-bench tune --env ENV --model FILE`` writes
``FILE.decision.toml`` beside the model (:mod:`rmm_guardians.lrmm.decision`).

Each choice and how it differs from the original: docs/decisions/0007-datasets-and-models.md.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from rmm_envs.risk.dataset import load_dataset
from rmm_guardians.lrmm.model import ACTIVATIONS, LRMMModel

if TYPE_CHECKING:
    import torch

__all__ = ["TrainConfig", "main", "split_by_config", "train"]


class TrainConfig:
    def __init__(
        self,
        hidden=(64,),
        activation="sigmoid",
        output_bias=False,
        epochs=300,
        batch_size=64,
        lr=1e-3,
        seed=0,
        val_frac=0.15,
        test_frac=0.15,
        features=None,
        select="best",
        dtype="float64",
        patience=None,
        head="auto",
    ):
        if not hidden or any(int(h) != h or h < 1 for h in hidden):
            raise ValueError(f"hidden must be one or more positive layer sizes, got {hidden!r}")
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {ACTIVATIONS}, got {activation!r}")
        if int(epochs) != epochs or epochs < 1:
            raise ValueError(f"epochs must be an integer >= 1, got {epochs!r}")
        if int(batch_size) != batch_size or batch_size < 1:
            raise ValueError(f"batch_size must be an integer >= 1, got {batch_size!r}")
        if not (lr > 0 and np.isfinite(lr)):
            raise ValueError(f"lr must be a finite number > 0, got {lr!r}")
        if head not in ("auto", "none"):
            raise ValueError(f"head must be 'auto' or 'none', got {head!r}")
        if not (0 < val_frac < 1 and 0 < test_frac < 1 and val_frac + test_frac < 1):
            raise ValueError(
                f"val_frac and test_frac must be in (0, 1) with a sum below 1, got {val_frac}, {test_frac}"
            )
        if select not in ("best", "last"):
            raise ValueError(f"select must be 'best' or 'last', got {select!r}")
        if dtype not in ("float32", "float64"):
            raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
        self.hidden = [int(h) for h in hidden]
        self.activation = activation
        self.output_bias = bool(output_bias)
        self.epochs = int(epochs)
        self.batch_size = int(batch_size)
        self.lr = float(lr)
        self.seed = int(seed)
        self.val_frac = float(val_frac)
        self.test_frac = float(test_frac)
        self.features = None if features is None else [int(f) for f in features]
        self.select = select
        self.dtype = dtype
        self.patience = patience
        self.head = head

    def as_dict(self) -> dict:
        return dict(vars(self))


def split_by_config(config_ids: np.ndarray, val_frac: float, test_frac: float, seed: int):
    """Boolean masks (train, val, test) assigning whole configurations to one split each."""
    configs = np.unique(config_ids)
    if configs.shape[0] < 3:
        raise ValueError(
            f"the dataset has {configs.shape[0]} obstacle configuration(s); a split by configuration "
            "needs at least 3 (train, validation and test each get whole configurations)"
        )
    perm = np.random.default_rng(seed).permutation(configs)
    n_test = max(1, int(round(test_frac * configs.shape[0])))
    n_val = max(1, int(round(val_frac * configs.shape[0])))
    test_c, val_c = perm[:n_test], perm[n_test : n_test + n_val]
    test = np.isin(config_ids, test_c)
    val = np.isin(config_ids, val_c)
    return ~(test | val), val, test


def fit_minmax(x: np.ndarray):
    lo, hi = x.min(axis=0), x.max(axis=0)
    rng = hi - lo
    scale = np.where(rng > 0, 1.0 / np.where(rng > 0, rng, 1.0), 1.0)  # constant feature: pass through
    return lo.astype(float), scale.astype(float)


def _metrics(model: LRMMModel, obs, y, cand=None) -> dict:
    if len(y) == 0:
        return {"mse": None, "mae": None, "max_abs_err": None, "n": 0}
    out = model.predict_all(obs)
    e = out[:, 0] - y
    m: dict[str, Any] = {
        "mse": float(np.mean(e * e)),
        "mae": float(np.mean(np.abs(e))),
        "max_abs_err": float(np.max(np.abs(e))),
        "n": int(len(y)),
    }
    if cand is not None and model.candidates is not None:
        pc = out[:, 1:]
        picked = cand[np.arange(len(y)), np.argmin(pc, axis=1)]
        m["candidates"] = {
            "mse": float(np.mean((pc - cand) ** 2)),
            "mae": float(np.mean(np.abs(pc - cand))),
            "regret": float(np.mean(picked - cand.min(axis=1))),
            "picked_risk": float(np.mean(picked)),
            "best_risk": float(np.mean(cand.min(axis=1))),
        }
    return m


class TrainingDiverged(ValueError):
    """The loss became NaN or inf."""


def train(dataset, cfg: TrainConfig, log=print) -> LRMMModel:
    """Train on a :class:`rmm_envs.risk.datagen.Dataset`; returns the numpy model with metrics."""
    import torch  # lazy: an optional heavy dependency (the train extra)

    if len(dataset) == 0:
        raise ValueError("the dataset is empty")
    obs_all = dataset.obs.astype(np.float64)
    y_all = dataset.risk.astype(np.float64)
    cand_all = None
    if cfg.head == "auto" and getattr(dataset, "candidate_risk", None) is not None:
        cand_all = np.asarray(dataset.candidate_risk, dtype=np.float64)
        cands = dataset.meta.get("estimator", {}).get("candidates")
        if cands is None or len(cands) != cand_all.shape[1]:
            raise ValueError(
                f"the dataset has {cand_all.shape[1]} candidate_risk columns but its metadata lists "
                f"candidates {cands!r}"
            )
    targets = y_all[:, None] if cand_all is None else np.column_stack([y_all, cand_all])
    if not np.all(np.isfinite(obs_all)) or not np.all(np.isfinite(targets)):
        raise ValueError("the dataset holds non-finite observations or labels")
    obs_dim = obs_all.shape[1]
    feats = list(range(obs_dim)) if cfg.features is None else cfg.features
    if any(f < 0 or f >= obs_dim for f in feats):
        raise ValueError(f"features {feats} fall outside the {obs_dim} observation values")
    tr, va, te = split_by_config(dataset.config_id, cfg.val_frac, cfg.test_frac, cfg.seed)
    x = obs_all[:, feats]
    lo, scale = fit_minmax(x[tr])

    torch.set_num_threads(1)
    torch.manual_seed(cfg.seed)
    dt = torch.float64 if cfg.dtype == "float64" else torch.float32
    layers: list[torch.nn.Module] = []
    n_in = len(feats)
    for h in cfg.hidden:
        layers.append(torch.nn.Linear(n_in, h, dtype=dt))
        layers.append(
            {"sigmoid": torch.nn.Sigmoid(), "tanh": torch.nn.Tanh(), "relu": torch.nn.ReLU(), "elu": torch.nn.ELU()}[
                cfg.activation
            ]
        )
        n_in = h
    layers.append(torch.nn.Linear(n_in, targets.shape[1], bias=cfg.output_bias, dtype=dt))
    layers.append(torch.nn.Sigmoid())
    net = torch.nn.Sequential(*layers)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)

    xt = torch.as_tensor((x[tr] - lo) * scale, dtype=dt)
    yt = torch.as_tensor(targets[tr], dtype=dt)
    xv = torch.as_tensor((x[va] - lo) * scale, dtype=dt)
    yv = torch.as_tensor(targets[va], dtype=dt)
    gen = torch.Generator().manual_seed(cfg.seed)
    best: tuple[float, dict[str, torch.Tensor] | None, int] = (float("inf"), None, -1)
    t0 = time.perf_counter()
    n = xt.shape[0]
    stale = 0
    history = []
    for epoch in range(cfg.epochs):
        net.train()
        perm = torch.randperm(n, generator=gen)
        for i in range(0, n, cfg.batch_size):
            idx = perm[i : i + cfg.batch_size]
            opt.zero_grad(set_to_none=True)
            loss = torch.nn.functional.mse_loss(net(xt[idx]), yt[idx])
            if not torch.isfinite(loss):
                raise TrainingDiverged(
                    f"training diverged: the loss became {loss.item()} at epoch {epoch + 1}, batch "
                    f"{i // cfg.batch_size + 1} (lr {cfg.lr}); lower --lr.  No model was written"
                )
            loss.backward()
            opt.step()
        net.eval()
        with torch.no_grad():
            val_mse = float(torch.nn.functional.mse_loss(net(xv), yv))
        if not np.isfinite(val_mse):
            raise TrainingDiverged(
                f"training diverged: the validation loss became {val_mse} after epoch {epoch + 1} "
                f"(lr {cfg.lr}); lower --lr.  No model was written"
            )
        history.append(val_mse)
        if val_mse < best[0]:
            best = (val_mse, {k: v.detach().clone() for k, v in net.state_dict().items()}, epoch)
            stale = 0
        else:
            stale += 1
        if epoch % max(1, cfg.epochs // 20) == 0 or epoch == cfg.epochs - 1:
            log(
                f"epoch {epoch + 1:5d}/{cfg.epochs}  val mse {val_mse:.5f}  (best {best[0]:.5f} at {best[2] + 1})  "
                f"{time.perf_counter() - t0:6.1f} s"
            )
        if cfg.patience and stale >= cfg.patience:
            log(f"stopping: no validation improvement in {cfg.patience} epochs")
            break
    wall = time.perf_counter() - t0
    if cfg.select == "best":
        assert best[1] is not None  # epochs >= 1, and the first epoch's finite loss beats inf
        net.load_state_dict(best[1])
    linears = [m for m in net if isinstance(m, torch.nn.Linear)]
    weights = [
        (m.weight.detach().double().numpy().copy(), None if m.bias is None else m.bias.detach().double().numpy().copy())
        for m in linears
    ]

    names = dataset.meta.get("feature_names") or [f"obs[{i}]" for i in range(obs_dim)]
    meta = {
        "env_id": dataset.meta["env_id"],
        "obs_dim": obs_dim,
        "features": feats,
        "feature_names": [names[i] for i in feats],
        "hidden": cfg.hidden,
        "activation": cfg.activation,
        "output_bias": cfg.output_bias,
        "labeller": dataset.meta.get("estimator"),
        "data_sha256": dataset.sha256,
        "data": {
            "n_rows": len(dataset),
            "configs": int(np.unique(dataset.config_id).shape[0]),
            "seed": dataset.meta.get("seed"),
            "samples_per_config": dataset.meta.get("samples_per_config"),
        },
        "training": cfg.as_dict()
        | {
            "wall_seconds": wall,
            "best_epoch": best[2] + 1,
            "epochs_run": epoch + 1,
            "selected_epoch": best[2] + 1 if cfg.select == "best" else epoch + 1,
            "val_mse_history": history,
            "torch": torch.__version__,
            "numpy": np.__version__,
            "python": platform.python_version(),
        },
        "split": {
            "by": "configuration",
            "train_configs": sorted(np.unique(dataset.config_id[tr]).tolist()),
            "val_configs": sorted(np.unique(dataset.config_id[va]).tolist()),
            "test_configs": sorted(np.unique(dataset.config_id[te]).tolist()),
        },
    }
    if cand_all is not None:
        meta["candidates"] = [[float(v) for v in c] for c in dataset.meta["estimator"]["candidates"]]
        meta["candidate_hold"] = float(dataset.meta["estimator"]["candidate_hold"])
    model = LRMMModel(weights, lo, scale, meta)
    c = (lambda m: None) if cand_all is None else (lambda m: cand_all[m])
    model.meta["metrics"] = {
        "train": _metrics(model, obs_all[tr], y_all[tr], c(tr)),
        "val": _metrics(model, obs_all[va], y_all[va], c(va)),
        "test": _metrics(model, obs_all[te], y_all[te], c(te)),
    }
    model.torch_net = net  # for tests comparing numpy and torch inference
    return model


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rmm-train",
        description="Train a learned risk metric map on an rmm-datagen dataset "
        "(split by obstacle configuration) and save it as an LRMM model file.",
    )
    p.add_argument("--data", required=True, help="dataset directory written by rmm-datagen")
    p.add_argument("--out", required=True, help="model file to write (.npz)")
    p.add_argument("--hidden", type=int, nargs="+", default=[64], help="hidden layer sizes (default: 64)")
    p.add_argument(
        "--activation", default="sigmoid", choices=list(ACTIVATIONS), help="hidden activation (default: %(default)s)"
    )
    p.add_argument("--output-bias", action="store_true", help="give the output layer a bias (the paper's has none)")
    p.add_argument("--epochs", type=int, default=300, help="training epochs (default: %(default)s)")
    p.add_argument(
        "--patience", type=int, default=None, help="stop after this many epochs without validation improvement"
    )
    p.add_argument("--batch-size", type=int, default=64, help="mini-batch size (default: %(default)s)")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (default: %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="seed for the split, initialisation and shuffling (default: %(default)s)"
    )
    p.add_argument(
        "--val-frac", type=float, default=0.15, help="fraction of configurations for validation (default: %(default)s)"
    )
    p.add_argument(
        "--test-frac", type=float, default=0.15, help="fraction of configurations for test (default: %(default)s)"
    )
    p.add_argument("--features", type=int, nargs="+", default=None, help="observation indices to use (default: all)")
    p.add_argument(
        "--select",
        default="best",
        choices=["best", "last"],
        help="keep the best-validation or the last epoch (default: %(default)s)",
    )
    p.add_argument(
        "--dtype", default="float64", choices=["float64", "float32"], help="training precision (default: %(default)s)"
    )
    p.add_argument(
        "--head",
        default="auto",
        choices=["auto", "none"],
        help="auto: add one output per candidate control when the dataset has candidate labels; "
        "none: risk only (default: %(default)s)",
    )
    p.add_argument("--quiet", action="store_true", help="no per-epoch log")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cfg = TrainConfig(
            hidden=args.hidden,
            activation=args.activation,
            output_bias=args.output_bias,
            epochs=args.epochs,
            batch_size=args.batch_size,
            lr=args.lr,
            seed=args.seed,
            val_frac=args.val_frac,
            test_frac=args.test_frac,
            features=args.features,
            select=args.select,
            dtype=args.dtype,
            patience=args.patience,
            head=args.head,
        )
        ds = load_dataset(args.data)
        model = train(ds, cfg, log=(lambda *a: None) if args.quiet else print)
    except (ValueError, FileNotFoundError) as e:
        print(f"rmm-train: error: {e}", file=sys.stderr)
        return 2
    model.meta["training"]["command"] = "rmm-train " + " ".join(sys.argv[1:] if argv is None else argv)
    model.save(args.out)
    m = model.meta["metrics"]
    print(
        f"saved {args.out} (trained in {model.meta['training']['wall_seconds']:.1f} s, "
        f"best epoch {model.meta['training']['best_epoch']})"
    )
    for split in ("train", "val", "test"):
        s = m[split]
        print(f"  {split:5s}: n={s['n']:6d}  MSE {s['mse']:.3e}  MAE {s['mae']:.3e}  max |err| {s['max_abs_err']:.3f}")
        if "candidates" in s:
            cs = s["candidates"]
            print(
                f"         candidates: MSE {cs['mse']:.3e}  MAE {cs['mae']:.3e}  regret {cs['regret']:.4f} "
                f"(picked {cs['picked_risk']:.4f}, best {cs['best_risk']:.4f})"
            )
    print(json.dumps({k: {"mse": v["mse"], "mae": v["mae"]} for k, v in m.items()}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
