"""``rmm-envs``: small utilities around the environments.

``rmm-envs demo`` runs a short episode of ``Dubins4DParallel-v0`` with a guardian that never
takes control (the reckless driver alone) and prints what happened.
"""

from __future__ import annotations

import argparse
import sys
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401  (registers the environments)


def _demo(args: argparse.Namespace) -> int:
    env = gym.make(args.env)
    inactive = {"active_ctrl": 0, "turnrate_ctrl": np.zeros(1, np.float32), "accel_ctrl": np.zeros(1, np.float32)}
    outcomes: dict[str, int] = {}
    t0 = time.perf_counter()
    steps = 0
    for ep in range(args.episodes):
        obs, info = env.reset(seed=args.seed + ep)
        done = False
        while not done:
            obs, reward, terminated, truncated, info = env.step(inactive)
            steps += 1
            done = terminated or truncated
        st = info["episode"]
        outcomes[info["outcome"]] = outcomes.get(info["outcome"], 0) + 1
        print(
            f"episode {ep:3d} seed {args.seed + ep:5d}: {info['outcome']:9s} after {st['n_env_steps']:4d} steps, "
            f"{st['cum_sim_time']:6.1f} s simulated, final speed {st['final_speed']:.2f} m/s"
        )
    dt = time.perf_counter() - t0
    print(f"\n{args.env}, driver alone, {args.episodes} episodes: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    print(f"{steps} steps in {dt:.2f} s ({steps / dt:.0f} steps/s)")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="rmm-envs", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run a few episodes with the driver alone and print the outcomes")
    demo.add_argument("--env", default="Dubins4DParallel-v0", choices=list(rmm_envs.ENV_IDS))
    demo.add_argument("--episodes", type=int, default=8)
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_demo)
    args = parser.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
