"""``rmm-envs``: small utilities around the environments.

``rmm-envs demo`` runs a few episodes of a parallel-autonomy env (default
``Dubins4DParallel-v0``; 8 episodes from seed 0, enough to see both goals and collisions) with a guardian
that never takes control, so the reckless driver alone decides, and prints each outcome.
Speeds are in m/s; an env measured in other units (the maze, in pixels) also gets its own
unit in brackets, converted at the scale the env states (``0.10 m/s (10.00 px/s)``).
The "no guardian" action is read off the env's action space: ``active_ctrl`` 0 and every
control field zero.  An env whose action space has no ``active_ctrl`` is refused by name.  The figure commands that
need a learned model are ``rmm-bench riskmap`` (the paper's Fig. 1) and ``rmm-bench quadrisk``
(Fig. 3).
"""

from __future__ import annotations

import argparse
import sys
import time

import gymnasium as gym
from gymnasium import spaces

import rmm_envs  # noqa: F401  (registers the environments)
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.defaults import DEFAULT_ENV


def driver_only_action(space: spaces.Space, env_id: str) -> dict:
    """The action that leaves the step to the built-in driver (:func:`rmm_envs.autonomy.inactive`)."""
    if not isinstance(space, GuardianActionSpace):
        raise ValueError(
            f"env {env_id} has no guardian action to leave to its driver: its action space is {space}, "
            "not a GuardianActionSpace (the parallel-autonomy contract, rmm_envs.autonomy)"
        )
    return space.inactive()


def speed_text(speed: float, env) -> str:
    """A speed in m/s; for an env whose lengths are in another unit (its ``length_unit``, e.g. the
    maze's ``"px"``), converted with its ``metres_per_unit`` and followed by the native value in
    brackets: ``0.10 m/s (10.00 px/s)``."""
    unit = getattr(env, "length_unit", "m")
    if unit == "m":
        return f"{speed:.2f} m/s"
    return f"{speed * float(env.metres_per_unit):.2f} m/s ({speed:.2f} {unit}/s)"


def _demo(args: argparse.Namespace) -> int:
    if args.episodes < 1:
        print(f"rmm-envs demo: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    env = gym.make(args.env)
    try:
        inactive = driver_only_action(env.action_space, args.env)
    except ValueError as e:
        env.close()
        print(f"rmm-envs demo: error: {e}", file=sys.stderr)
        return 2
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
        st = info["episode_stats"]
        outcomes[info["outcome"]] = outcomes.get(info["outcome"], 0) + 1
        speed = f", final speed {speed_text(st['final_speed'], env.unwrapped)}" if "final_speed" in st else ""
        print(
            f"episode {ep:3d} seed {args.seed + ep:5d}: {info['outcome']:9s} after {st['n_env_steps']:4d} steps, "
            f"{st['cum_sim_time']:6.1f} s simulated{speed}"
        )
    dt = time.perf_counter() - t0
    print(
        f"\n{args.env}, driver alone, {args.episodes} episodes: "
        + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items()))
    )
    print(f"{steps} steps in {dt:.2f} s ({steps / dt:.0f} steps/s)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rmm-envs", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run a few episodes with the driver alone and print the outcomes")
    demo.add_argument(
        "--env",
        default=DEFAULT_ENV,
        choices=list(rmm_envs.GUARDIAN_ENV_IDS),
        help="an env with a built-in driver (default: %(default)s)",
    )
    demo.add_argument("--episodes", type=int, default=8)
    demo.add_argument("--seed", type=int, default=0)
    demo.set_defaults(func=_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
