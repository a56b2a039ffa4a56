"""Tutorial: label a dataset with the sampling-tree estimator and train a risk map on it.

    python docs/examples/label_and_train.py --out lrmm-tutorial               # small and quick
    python docs/examples/label_and_train.py --configs 274 --samples 128 --epochs 300  # the paper's scale

Steps: (1) rmm-datagen's Python API labels states of procedurally generated obstacle
configurations; (2) rmm-train's API trains the paper's network with a split by configuration;
(3) the saved model drives the LRMM guardian for one episode.
"""

import argparse
import tempfile
from pathlib import Path

import gymnasium as gym

import rmm_envs  # noqa: F401  (registers the environments)
from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.train import TrainConfig, train


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=None, help="working directory (default: a temporary one)")
    ap.add_argument("--configs", type=int, default=12)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument("--branches", type=int, default=32)
    ap.add_argument("--epochs", type=int, default=20)
    args = ap.parse_args(argv)
    work = Path(args.out or tempfile.mkdtemp(prefix="lrmm-tutorial-"))

    # 1. Algorithm 2: configurations -> valid states -> observations -> risk labels
    cfg = DatagenConfig(
        env_id="Dubins4DGuarded-v0",
        configs=args.configs,
        samples_per_config=args.samples,
        branches=args.branches,
        depth=2,
        horizon=2.0,
        n_steps=8,
        seed=0,
    )
    manifest = generate(cfg, work / "data", workers=2, progress=False)
    data = load_dataset(work / "data")
    print(f"labelled {len(data)} states from {args.configs} configurations; mean risk {data.risk.mean():.3f}")
    assert len(data) == args.configs * args.samples and 0.0 <= data.risk.min() <= data.risk.max() <= 1.0

    # 2. train the paper's network (17 -> 64 sigmoid -> 1 sigmoid), split by configuration
    model = train(data, TrainConfig(epochs=args.epochs, seed=0), log=lambda *a: None)
    model.save(work / "model.npz")
    for split, m in model.meta["metrics"].items():
        print(f"{split:5s} MSE {m['mse']:.4f} MAE {m['mae']:.4f} ({m['n']} samples)")
    # every split was scored, on disjoint configurations that together cover the dataset
    assert set(model.meta["metrics"]) == {"train", "val", "test"}
    assert sum(m["n"] for m in model.meta["metrics"].values()) == len(data)

    # 3. use it as a guardian.  This model predicts the risk only (no action-conditioned head,
    #    no stored decision), so say how to act: take control above 0.3 and brake toward the
    #    more open side (the paper's manoeuvre, the strategy BrakeTurn)
    env = gym.make("Dubins4DParallel-v0", clock="fixed:1")
    guardian = LRMMGuardian(work / "model.npz", threshold=0.3, strategies="BrakeTurn")
    obs, info = env.reset(seed=123)
    guardian.reset(seed=123, observation_space=env.observation_space, action_space=env.action_space)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(guardian.act(obs, info))
        done = terminated or truncated
    ep = info["episode_stats"]
    assert info["outcome"] in ("goal", "collision", "timeout")
    print(
        f"episode: {info['outcome']} after {ep['n_env_steps']} steps, guardian in control "
        f"{100 * ep['active_ctrl_sim_time'] / ep['cum_sim_time']:.0f}% of the time; dataset {manifest['dataset_sha256'][:12]}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
