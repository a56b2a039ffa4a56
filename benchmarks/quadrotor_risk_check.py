"""Does the quadrotor's command-policy risk carry information, and does the shipped model hold?

Run: ``python -m benchmarks.quadrotor_risk_check [--resets 200] [--episodes 16] [--seed 0] [--variant risk]``
(``--variant act``: the model ``lrmm`` reads, with the action-conditioned head).

1. **Labels at reset states** (issue target: mean in [0.1, 0.9], standard deviation >= 0.15):
   the start state of ``--resets`` episodes of ``QuadrotorRoomGuarded-v0`` (env seeds
   ``seed ..``), each labelled by the sampling tree of the shipped model's labels (its
   ``meta["labeller"]``: random velocity commands to the stabilising controller, each held for
   one tree level), and the same states under the paper's labelling (``QuadrotorScene``:
   random thrust and moments, n = 32, m = 2, 2 s, 8 points) for comparison.
2. **The model on the pilot's states**: the pilot alone flies ``--episodes`` episodes (fixed
   1 ms clock); every 5th state, and every state of the last 2 s before a collision, is
   labelled and compared with the model's risk of its observation: mean absolute error next
   to that of a constant predictor (the labels' mean).
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from rmm_envs.risk.estimator import RiskEstimator
from rmm_envs.systems.quadrotor.scene import QuadrotorScene
from rmm_guardians.lrmm.model import default_model_path, load_model

ENV = "QuadrotorRoomParallel-v0"


def estimator(scene, lab):
    return RiskEstimator(
        scene,
        branches=lab["branches"],
        depth=lab["depth"],
        horizon=lab["horizon"],
        n_steps=lab["n_steps"],
        metric=lab["metric"],
        leaf=lab["leaf"],
    )


def reset_labels(resets: int, seed: int, lab) -> tuple[np.ndarray, np.ndarray]:
    env = gym.make("QuadrotorRoomGuarded-v0").unwrapped
    rng = np.random.default_rng(seed)
    ours, paper = [], []
    for i in range(resets):
        _, info = env.reset(seed=seed + i)
        s = info["state"][None]
        ours.append(estimator(env.risk_scene(), lab).estimate(s, rng).risk[0])
        paper.append(RiskEstimator(QuadrotorScene(env.room, env.params)).estimate(s, rng).risk[0])
    env.close()
    return np.array(ours), np.array(paper)


def visited(episodes: int, seed: int, model, lab):
    env = gym.make(ENV, clock="fixed:1")
    rng = np.random.default_rng(seed)
    labels, preds, doomed = [], [], []
    for ep in range(episodes):
        obs, info = env.reset(seed=seed + ep)
        states, observations, times = [info["state"]], [obs], [0.0]
        while True:
            obs, _, te, tr, info = env.step(env.action_space.inactive())
            if te or tr:
                break
            states.append(info["state"])
            observations.append(obs)
            times.append(info["sim_time"])
        end = info["sim_time"]
        dm = np.array([info["outcome"] == "collision" and end - t <= 2.0 for t in times])
        keep = dm.copy()
        keep[::5] = True
        st = np.array(states)[keep]
        labels.append(estimator(env.unwrapped.risk_scene(), lab).estimate(st, rng).risk)
        preds.append(np.atleast_1d(model.predict(np.array(observations)[keep].astype(float))))
        doomed.append(dm[keep])
    env.close()
    return np.concatenate(labels), np.concatenate(preds), np.concatenate(doomed)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resets", type=int, default=200)
    p.add_argument("--episodes", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--variant", default="risk", choices=["risk", "act"], help="which shipped model (default: %(default)s)"
    )
    args = p.parse_args(argv)
    model = load_model(default_model_path(ENV, variant=args.variant))
    lab = model.meta["labeller"]
    ours, paper = reset_labels(args.resets, args.seed, lab)
    print(f"labels at {args.resets} reset states (env seeds {args.seed}-{args.seed + args.resets - 1}):")
    print(
        f"  command policy ({lab['branches']} branches, {lab['depth']} levels of {lab['horizon']} s): mean {ours.mean():.3f}, "
        f"std {ours.std():.3f} (targets: mean in [0.1, 0.9], std >= 0.15)"
    )
    print(
        f"  paper's labelling (random thrust and moments, 32 x 2 levels of 2 s): mean {paper.mean():.3f}, std {paper.std():.3f}"
    )
    y, f, d = visited(args.episodes, args.seed, model, lab)
    const = np.abs(y - y.mean()).mean()
    print(
        f"{y.size} states the pilot visited alone in {args.episodes} episodes: labels mean {y.mean():.3f}, std {y.std():.3f}; "
        f"model MAE {np.abs(y - f).mean():.4f} (constant predictor {const:.4f}, ratio {np.abs(y - f).mean() / const:.2f})"
    )
    if d.any():
        print(
            f"  last 2 s before a collision ({d.sum()} states): label {y[d].mean():.3f}, model {f[d].mean():.3f}; "
            f"other states: label {y[~d].mean():.3f}, model {f[~d].mean():.3f}"
        )


if __name__ == "__main__":
    main()
