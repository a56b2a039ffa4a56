"""Map env performance: ``Dubins4DMapGuarded-v0`` (pymunk queries) against ``Dubins4DGuarded-v0``
(compiled circle kernels), both measured in the same run, so the ratios are what a shared
machine can compare.

Run: ``python -m benchmarks.perf_map``.  Prints, with the driver in control (blocking envs,
resets included): steps per CPU second of ``Dubins4DGuarded-v0``, of ``Dubins4DMapGuarded-v0`` on the
shipped example map (circles, polygons, walls) and on a map of five circles (those of
``Dubins4DGuarded-v0``'s seed-0 episode); then the time of risk labels (the paper's tree, 32
branches, depth 2, 64 states) on that circle map against the analytic circle scene.  The envs
are timed in turn within each repeat, on this process's CPU time (other processes' load
barely moves it), and the ratios are the medians of the per-repeat ratios.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from benchmarks._timing import fmt_us, median_time
from rmm_envs.risk import RiskEstimator
from rmm_envs.systems.dubins4d_map.env import Dubins4DMapEnv


def cpu_steps_per_second(env, episodes: int) -> float:
    """Steps per CPU second of ``env`` driven by the inactive guardian over seeds ``0 .. episodes - 1``."""
    inactive = env.unwrapped.action_space.inactive()
    n = 0
    t0 = time.process_time()
    for ep in range(episodes):
        env.reset(seed=ep)
        done = False
        while not done:
            _, _, te, tr, _ = env.step(inactive)
            n += 1
            done = te or tr
    return n / (time.process_time() - t0)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    circles_env = gym.make("Dubins4DGuarded-v0").unwrapped
    circles_env.reset(seed=0)
    circles = circles_env.scene.obstacles
    circle_map = [{"circle": c.tolist()} for c in circles]
    runs = {
        "Dubins4DGuarded-v0": ("Dubins4DGuarded-v0", {}),
        "Dubins4DMapGuarded-v0, example map": ("Dubins4DMapGuarded-v0", {}),
        "Dubins4DMapGuarded-v0, 5 circles": ("Dubins4DMapGuarded-v0", {"map": circle_map}),
    }
    envs = {name: gym.make(env_id, **kw) for name, (env_id, kw) in runs.items()}
    rates: dict[str, list[float]] = {name: [] for name in runs}
    for env in envs.values():  # compile and warm every env before timing
        env.reset(seed=0)
        env.step(env.unwrapped.action_space.inactive())
    for _ in range(args.repeats):
        for name, env in envs.items():
            rates[name].append(cpu_steps_per_second(env, args.episodes))
    for name in runs:
        print(
            f"{name:30s} {statistics.median(rates[name]):8.0f} steps per CPU second "
            f"(median of {args.repeats} runs of {args.episodes} episodes)"
        )
    base = rates["Dubins4DGuarded-v0"]
    for name in list(runs)[1:]:
        ratio = statistics.median(b / r for b, r in zip(base, rates[name], strict=True))  # one rate per repeat
        print(f"step time ratio {name} / Dubins4DGuarded-v0 (same run): {ratio:.2f}x")

    m = Dubins4DMapEnv(map=circle_map)
    state, goal = circles_env.true_state, circles_env.scene.goal
    m.reset(seed=0, options={"state": state, "goal": goal})
    states = circles_env.sample_states(np.random.default_rng(0), 64)
    t = {}
    for name, scene in (("circles (analytic)", circles_env.risk_scene()), ("circle map (pymunk)", m.risk_scene())):
        est = RiskEstimator(scene, branches=32, depth=2)
        t[name] = median_time(lambda est=est: est.estimate(states, np.random.default_rng(1)), repeats=3)
        print(f"risk labels of 64 states, {name:20s} {fmt_us(t[name])}")
    print(
        f"labelling time ratio pymunk / analytic (same run): {t['circle map (pymunk)'] / t['circles (analytic)']:.1f}x"
    )


if __name__ == "__main__":
    main()
