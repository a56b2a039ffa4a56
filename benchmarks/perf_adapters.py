"""Labels/s of the risk adapters (rmm_envs.adapters) next to the straightforward loop, both
measured in the same run on the same states with the same tree.

Run: ``python -m benchmarks.perf_adapters [--labels 64] [--loop-labels 8] [--envs CartPole-v1 InvertedPendulum-v5]``.

For each env: the batched scene (numpy CartPole/Pendulum dynamics; ``mujoco.rollout`` for
the MuJoCo envs) labels ``--labels`` sampled states with ``n = 32, m = 2`` at the adapter's
default horizon; the straightforward loop labels ``--loop-labels`` of the same states with the
same estimator over :func:`rmm_envs.adapters.step_by_step` (the env's own ``step`` called once
per env step, state restored per branch).  Both run the same Algorithm 1 (only live nodes are
expanded) with the same generator seed, and the labels of the shared states are checked equal
(up to 1e-12).  The ratio is the batched scene's labels/s on those same states (same tree,
same controls) over the loop's, so it compares like with like; the batched labels/s on all
``--labels`` states is printed too (labels near failure cost less: failed branches are not
expanded).  Medians of ``--repeats`` runs of the batched scene; one run of the loop.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

from rmm_envs.adapters import adapt, step_by_step
from rmm_envs.risk import RiskEstimator

FAILURES = {"Pendulum-v1": lambda s: np.abs(s[:, 1]) > 6.0}


def _rate(estimator, states, seed: int, repeats: int) -> tuple[float, np.ndarray]:
    times, risk = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        risk = estimator.estimate(states, np.random.default_rng(seed)).risk
        times.append(time.perf_counter() - t0)
    return states.shape[0] / statistics.median(times), risk


def measure(env_id: str, labels: int, loop_labels: int, repeats: int, seed: int = 0) -> dict:
    env = gym.make(env_id)
    env.reset(seed=seed)
    ad = adapt(env, FAILURES.get(env_id))
    states = ad.sample_states(np.random.default_rng(seed), labels)
    kw = dict(branches=32, depth=2, horizon=ad.scene.default_horizon)
    fast, r_fast = _rate(RiskEstimator(ad.scene, **kw), states, seed, repeats)
    # the same controls: draw the whole tree for the shared roots once and give it to both
    few = states[:loop_labels]
    est_fast = RiskEstimator(ad.scene, **kw)
    controls = est_fast.draw_controls(np.random.default_rng(seed), few.shape[0])
    slow_est = RiskEstimator(step_by_step(ad), **kw)
    t0 = time.perf_counter()
    r_slow = slow_est.estimate(few, controls=controls).risk
    slow = few.shape[0] / (time.perf_counter() - t0)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r_check = est_fast.estimate(few, controls=controls).risk
        times.append(time.perf_counter() - t0)
    same = few.shape[0] / statistics.median(times)
    if np.max(np.abs(r_slow - r_check)) > 1e-12:
        raise AssertionError(f"{env_id}: batched and step-by-step labels differ: {r_check} vs {r_slow}")
    return {
        "env": env_id,
        "horizon": kw["horizon"],
        "batched_labels_per_s": fast,
        "batched_same_per_s": same,
        "loop_labels_per_s": slow,
        "ratio": same / slow,
        "mean_risk": float(np.mean(r_fast)),
        "mean_risk_same": float(np.mean(r_slow)),
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--labels", type=int, default=64, help="states labelled by the batched scene (default: %(default)s)")
    p.add_argument(
        "--loop-labels", type=int, default=8, help="states labelled by the step-by-step loop (default: %(default)s)"
    )
    p.add_argument(
        "--repeats", type=int, default=3, help="runs of the batched scene, median taken (default: %(default)s)"
    )
    p.add_argument("--envs", nargs="+", default=["CartPole-v1", "InvertedPendulum-v5"])
    args = p.parse_args(argv)
    print(
        f"{'env':26s} {'t (s)':>6s} {'batched/s (all)':>15s} {'mean risk':>9s} | {'batched/s':>9s} "
        f"{'loop/s':>8s} {'ratio':>6s} {'mean risk':>9s} (same states)"
    )
    for env_id in args.envs:
        r = measure(env_id, args.labels, args.loop_labels, args.repeats)
        print(
            f"{r['env']:26s} {r['horizon']:6.3f} {r['batched_labels_per_s']:15.1f} {r['mean_risk']:9.3f} | "
            f"{r['batched_same_per_s']:9.1f} {r['loop_labels_per_s']:8.2f} {r['ratio']:6.1f} {r['mean_risk_same']:9.3f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
