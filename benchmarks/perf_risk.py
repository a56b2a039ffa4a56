"""Risk-labelling performance (issue figures: labels/s and the ratio to a straightforward
implementation measured in the same run; memory of dataset generation).

Run: ``python -m benchmarks.perf_risk [--labels 256] [--naive-labels 4]``.

The straightforward baseline is Algorithm 1 as the original code ran it: recursion over the
tree, one ``scipy.integrate.odeint`` solve per branch (8 points, the speed clamp in the
right-hand side) and a Python loop over path points, segments and circles for the failure
check (exact circles, so it is faster than the original's shapely 64-gons).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import warnings

import numpy as np
from scipy.integrate import odeint

from rmm_envs.envs.dubins4d import Dubins4DCirclesEnv
from rmm_envs.risk import RiskEstimator


def _rhs(z, t, u1, u2):
    x, y, th, v = z
    dv = u2
    if (dv < 0 and v < 1e-3) or (dv > 0 and v > 2 - 1e-3):  # the original's clamp
        dv = 0.0
    return [v * math.cos(th), v * math.sin(th), u1, dv]


def _branch_fails(path, circles) -> bool:
    for j in range(len(path)):
        x, y = path[j, 0], path[j, 1]
        for cx, cy, r in circles:
            if (x - cx) ** 2 + (y - cy) ** 2 <= r * r:
                return True
        if j + 1 < len(path):
            x1, y1 = path[j + 1, 0], path[j + 1, 1]
            dx, dy = x1 - x, y1 - y
            dd = dx * dx + dy * dy
            for cx, cy, r in circles:
                s = 0.0 if dd == 0 else min(1.0, max(0.0, ((cx - x) * dx + (cy - y) * dy) / dd))
                px, py = x + s * dx - cx, y + s * dy - cy
                if px * px + py * py <= r * r:
                    return True
    return False


def naive_risk(state, circles, rng, n=32, m=2, t=2.0, n_steps=8) -> float:
    if m == 0:
        return 0.0
    vals = []
    times = np.linspace(0, t, n_steps)
    for _ in range(n):
        u1, u2 = rng.uniform(-0.25, 0.25), rng.uniform(-0.5, 0.5)
        path = odeint(_rhs, state, times, args=(u1, u2))
        if _branch_fails(path, circles):
            vals.append(1.0)
        else:
            vals.append(naive_risk(path[-1], circles, rng, n, m - 1, t, n_steps))
    return float(np.mean(vals))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--labels", type=int, default=256)
    ap.add_argument("--naive-labels", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args(argv)

    env = Dubins4DCirclesEnv()
    env.reset(seed=0)
    sc = env.risk_scene()
    rng = np.random.default_rng(0)
    states = env.sample_states(rng, args.labels)
    est = RiskEstimator(sc)  # n=32, m=2, t=2 s, 8 points, expected value
    est.estimate(states[:4], rng)  # warm-up
    rates = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        est.estimate(states, rng)
        rates.append(args.labels / (time.perf_counter() - t0))
    ours = statistics.median(rates)

    # odeint warns of excess work at the speed clamp's kink, as it did for the original
    warnings.filterwarnings("ignore", message="Excess work done")
    naive_states = states[: args.naive_labels]
    t0 = time.perf_counter()
    for s in naive_states:
        naive_risk(s, sc.obstacles, rng)
    naive = args.naive_labels / (time.perf_counter() - t0)
    print("Dubins4D labels, n=32, m=2, t=2 s, 8 points, one process")
    print(f"  batched estimator: median {ours:8.1f} labels/s over {args.repeats} runs of {args.labels} (target >= 500)")
    print(f"  straightforward (odeint per branch, loops): {naive:8.2f} labels/s over {args.naive_labels} labels")
    print(f"  ratio: {ours / naive:.0f}x (target >= 100x)")

    import gymnasium as gym

    import rmm_envs  # noqa: F401

    maze_env = gym.make("Dubins3DMaze-v0").unwrapped
    maze_env.reset(seed=0)
    maze_states = maze_env.sample_states(rng, args.labels)
    maze_est = RiskEstimator(maze_env.risk_scene())
    maze_est.estimate(maze_states[:4], rng)
    rates = []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        maze_est.estimate(maze_states, rng)
        rates.append(args.labels / (time.perf_counter() - t0))
    print("Dubins3D maze labels, n=32, m=2, t=2 s, 8 points, one process")
    print(f"  batched estimator: median {statistics.median(rates):8.1f} labels/s (target >= 200)")


if __name__ == "__main__":
    main()
