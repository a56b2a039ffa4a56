"""Does the shipped maze risk model hold on the states the reckless driver visits?

Run: ``python -m benchmarks.maze_model_check [--episodes 32] [--every 10] [--seed 0]``.

The maze model (``guardians/lrmm/models/dubins3d_maze.npz``) was trained on poses drawn
uniformly over ``Dubins3DMaze-v0``'s images.  ``Dubins3DMazeParallel-v0``'s driver visits a
different distribution (mid-corridor, heading along the path, and the corners it cuts).  This
script drives the driver alone (fixed 1 ms clock, episode seeds ``seed .. seed + episodes -
1``), keeps every ``every``-th pose, labels each with the sampling tree the model's labels
used (its ``meta["labeller"]``: 32 branches, 2 levels of 2 s, 8 path points, uniform turn
rates, expected collision), and compares the model's risk of the pose's rays with the label:
mean absolute error next to that of a constant predictor (the labels' mean), and the mean
label and prediction on the poses of the last 2 s before a collision against the rest.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from rmm_envs.risk.estimator import RiskEstimator
from rmm_guardians.lrmm.model import default_model_path, load_model


def visited(episodes: int, every: int, seed: int):
    """Poses, their observations, the episode's scene and whether they lie in the last 2 s before a collision."""
    env = gym.make("Dubins3DMazeParallel-v0", clock="fixed:1")
    out = []
    for ep in range(episodes):
        obs, info = env.reset(seed=seed + ep)
        states, observations, times = [info["state"]], [obs], [0.0]
        while True:
            obs, _, te, tr, info = env.step(env.action_space.inactive())
            states.append(info["state"])
            observations.append(obs)
            times.append(info["sim_time"])
            if te or tr:
                break
        end = info["sim_time"]
        doomed = np.array([info["outcome"] == "collision" and end - t <= 2.0 for t in times])
        keep = np.zeros(len(states), dtype=bool)
        keep[::every] = True
        keep |= doomed  # the poses before a collision are few: keep them all
        scene = env.unwrapped.risk_scene()
        out.append((np.array(states)[keep], np.array(observations)[keep], scene, doomed[keep]))
    return out


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=32)
    p.add_argument("--every", type=int, default=10)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    model = load_model(default_model_path("Dubins3DMazeParallel-v0", variant="act"))
    lab = model.meta["labeller"]
    rng = np.random.default_rng(args.seed)
    labels, preds, doomed = [], [], []
    for states, obs, scene, dm in visited(args.episodes, args.every, args.seed):
        est = RiskEstimator(
            scene,
            branches=lab["branches"],
            depth=lab["depth"],
            horizon=lab["horizon"],
            n_steps=lab["n_steps"],
            metric=lab["metric"],
            leaf=lab["leaf"],
        )
        labels.append(est.estimate(states, rng).risk)
        preds.append(np.atleast_1d(model.predict(obs[:, :8].astype(float))))
        doomed.append(dm)
    y, f, d = np.concatenate(labels), np.concatenate(preds), np.concatenate(doomed)
    const = np.abs(y - y.mean()).mean()
    print(
        f"{y.size} visited poses from {args.episodes} driver-alone episodes (seeds {args.seed}-{args.seed + args.episodes - 1})"
    )
    print(
        f"labels: mean {y.mean():.3f}, std {y.std():.3f}; model MAE {np.abs(y - f).mean():.4f} "
        f"(constant predictor {const:.4f}, ratio {np.abs(y - f).mean() / const:.2f})"
    )
    print(
        f"last 2 s before a collision ({d.sum()} poses): label {y[d].mean():.3f}, model {f[d].mean():.3f}; "
        f"other poses: label {y[~d].mean():.3f}, model {f[~d].mean():.3f}"
    )


if __name__ == "__main__":
    main()
