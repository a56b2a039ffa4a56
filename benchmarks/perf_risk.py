"""Risk-labelling performance (issue figures: labels/s and the ratio to a straightforward
implementation measured in the same run; memory of dataset generation).

Run: ``python -m benchmarks.perf_risk [--labels 256] [--naive-labels 4] [--repeats 5]
[--quad-labels 128]``.

Each system's labels are timed with the estimator's fused tree levels (``RiskEstimator(...,
fused=True)``, the default: one compiled loop propagates and tests each branch) and with today's
separate ``propagate`` and ``path_failed`` (``fused=False``, the reference), alternately on the same
states and controls, and the two labellings are checked to be the same bits on every repeat.  Rates
are medians over the repeats, in CPU time of this process (one core: what another job on the
machine takes from it does not count) and in wall time.

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
from dataclasses import fields

import gymnasium as gym
import numpy as np
from scipy.integrate import odeint

import rmm_envs  # noqa: F401  (registers the envs)
from rmm_envs.risk import RiskEstimator, RiskResult
from rmm_envs.risk.labelling import DatagenConfig, config_seeds, labelled_env
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv


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


def same_labels(a: RiskResult, b: RiskResult) -> bool:
    """Every field of two labellings, bit for bit."""
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) for f in fields(RiskResult))


def fused_against_reference(cases, repeats: int, seed: int = 0, **params) -> dict:
    """Median labels/s (CPU and wall) of the fused estimator and of the reference (``fused=False``),
    run alternately on each ``(scene, states)`` of ``cases`` (all of them per run) with the controls
    of one seed; ``ValueError`` if a repeat's labels differ."""
    ests = [
        {"fused": RiskEstimator(scene, **params), "reference": RiskEstimator(scene, fused=False, **params)}
        for scene, _ in cases
    ]
    for pair, (_, states) in zip(ests, cases, strict=True):  # warm-up: numba's compiled code loaded
        for est in pair.values():
            est.estimate(states[:2], np.random.default_rng(seed))
    n = sum(len(states) for _, states in cases)
    cpu: dict = {"fused": [], "reference": []}
    wall: dict = {"fused": [], "reference": []}
    for _ in range(repeats):
        for name in cpu:
            t0, c0 = time.perf_counter(), time.process_time()
            out = [
                pair[name].estimate(states, np.random.default_rng(seed))
                for pair, (_, states) in zip(ests, cases, strict=True)
            ]
            cpu[name].append(n / (time.process_time() - c0))
            wall[name].append(n / (time.perf_counter() - t0))
            if name == "fused":
                fused_out = out
            elif not all(same_labels(a, b) for a, b in zip(fused_out, out, strict=True)):
                raise ValueError("the fused estimator's labels differ from the reference's")
    return {f"{k}_{w}": statistics.median(d[k]) for w, d in (("cpu", cpu), ("wall", wall)) for k in cpu}


def report_fused(m: dict, repeats: int, n: int) -> None:
    print(
        f"  fused against the reference (fused=False, today's separate propagate and path_failed), alternating, "
        f"{repeats} runs of {n}, the same labels each run:"
    )
    print(
        f"    CPU time: {m['fused_cpu']:8.1f} against {m['reference_cpu']:7.1f} labels/s per core, "
        f"fused / reference {m['fused_cpu'] / m['reference_cpu']:.2f}x"
    )
    print(
        f"    wall time: {m['fused_wall']:7.1f} against {m['reference_wall']:7.1f} labels/s, "
        f"fused / reference {m['fused_wall'] / m['reference_wall']:.2f}x"
    )


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--labels", type=int, default=256)
    ap.add_argument("--naive-labels", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--quad-labels", type=int, default=128, help="quadrotor command-policy labels per run, 0 to skip")
    args = ap.parse_args(argv)

    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    sc = env.risk_scene()
    rng = np.random.default_rng(0)
    states = env.sample_states(rng, args.labels)
    m = fused_against_reference([(sc, states)], args.repeats)  # n=32, m=2, t=2 s, 8 points, expected value
    ours = m["fused_wall"]

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
    report_fused(m, args.repeats, args.labels)

    maze_env = gym.make("Dubins3DMaze-v0").unwrapped
    maze_env.reset(seed=0)
    maze_states = maze_env.sample_states(rng, args.labels)
    m = fused_against_reference([(maze_env.risk_scene(), maze_states)], args.repeats)
    print("Dubins3D maze labels, n=32, m=2, t=2 s, 8 points, one process")
    print(f"  batched estimator: median {m['fused_wall']:8.1f} labels/s (target >= 200)")
    report_fused(m, args.repeats, args.labels)

    if args.quad_labels:  # rooms differ much in clutter: the labels spread over the dataset's first 8 rooms
        cfg = DatagenConfig(env_id="QuadrotorRoomGuarded-v0", branches=16, depth=2, horizon=1.0, n_steps=5, seed=0)
        quad = labelled_env(cfg)
        cases = []
        for config in range(8):  # as rmm-datagen draws them (configuration seeds, states)
            env_seed, config_rng = config_seeds(cfg.seed, config)
            quad.reset(seed=env_seed)
            cases.append((quad.risk_scene(), quad.sample_states(config_rng, max(1, args.quad_labels // 8))))
        m = fused_against_reference(cases, args.repeats, **cfg.estimator_params())
        n = sum(len(st) for _, st in cases)
        print("quadrotor command-policy labels (QuadrotorRoomGuarded-v0), n=16, m=2, t=1 s, 5 points, one process,")
        print("the first 8 rooms of `rmm-datagen --seed 0`")
        print(f"  batched estimator: median {m['fused_wall']:8.1f} labels/s")
        report_fused(m, args.repeats, n)


if __name__ == "__main__":
    main()
