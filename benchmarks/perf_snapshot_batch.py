"""Labels/s of a simulator of your own, batched (its ``step_batch`` hook) against step by step
(the snapshot protocol's ``set_state`` and ``step``, one branch at a time), measured in the same
run on the same states with the same tree and checked to be the same labels, bit for bit.

Run: ``python -m benchmarks.perf_snapshot_batch [--labels 256] [--loop-labels 32] [--repeats 5]``.

Simulators: the tutorial's ``CartWall`` (docs/examples/own_simulator_wall.py: a cart before a
wall, the cheapest possible step) and ``PointRays`` (docs/examples/own_simulator_rays.py: a point
robot among three circles, the kind of simulator a user brings).  For each: the same estimator
(``n = 32, m = 2``, the simulator's default horizon) labels ``--loop-labels`` states step by step
and batched, on one tree of controls drawn once; the ratio is labels/s batched over step by step
on those states, each a median of ``--repeats`` runs.  The batched labels/s over ``--labels``
states is printed too.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from rmm_envs.adapters import SnapshotScene
from rmm_envs.risk import RiskEstimator

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"


def _simulators():
    if str(EXAMPLES) not in sys.path:
        sys.path.insert(0, str(EXAMPLES))
    from own_simulator_rays import PointRays
    from own_simulator_wall import CartWall

    return {"CartWall": CartWall, "PointRays": PointRays}


def _step_by_step(cls):
    """The same simulator without its batched hook: the snapshot path."""
    return type(f"{cls.__name__}StepByStep", (cls,), {"step_batch": None})


def _median_rate(estimator, states, controls, repeats: int) -> tuple[float, np.ndarray]:
    times, risk = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        risk = estimator.estimate(states, controls=controls).risk
        times.append(time.perf_counter() - t0)
    return states.shape[0] / statistics.median(times), risk


def measure(cls, labels: int, loop_labels: int, repeats: int, seed: int = 0) -> dict:
    sim = cls()
    states = np.asarray(sim.sample_states(np.random.default_rng(seed), labels), dtype=float)
    states = states[~sim.state_failed(states)]
    few = states[:loop_labels]
    kw = dict(branches=32, depth=2, horizon=cls.default_horizon)
    fast = RiskEstimator(SnapshotScene(cls(), default_horizon=cls.default_horizon), **kw)
    slow = RiskEstimator(SnapshotScene(_step_by_step(cls)(), default_horizon=cls.default_horizon), **kw)
    controls = fast.draw_controls(np.random.default_rng(seed), few.shape[0])
    slow_rate, r_slow = _median_rate(slow, few, controls, repeats)
    fast_rate, r_fast = _median_rate(fast, few, controls, repeats)
    if r_fast.tobytes() != r_slow.tobytes():
        raise AssertionError(f"{cls.__name__}: batched labels differ from step-by-step ones")
    all_controls = fast.draw_controls(np.random.default_rng(seed), states.shape[0])
    all_rate, _ = _median_rate(fast, states, all_controls, repeats)
    return {"step": slow_rate, "batched": fast_rate, "ratio": fast_rate / slow_rate, "all": all_rate, "n": len(few)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--labels", type=int, default=256, help="states labelled batched for the overall rate")
    ap.add_argument("--loop-labels", type=int, default=32, help="states labelled both ways for the ratio")
    ap.add_argument("--repeats", type=int, default=5, help="runs per median")
    args = ap.parse_args(argv)
    print(
        "| simulator | states | step by step [labels/s] | batched [labels/s] | ratio | batched, all states [labels/s] |"
    )
    print("|---|---|---|---|---|---|")
    for name, cls in _simulators().items():
        m = measure(cls, args.labels, args.loop_labels, args.repeats)
        print(f"| {name} | {m['n']} | {m['step']:.0f} | {m['batched']:.0f} | {m['ratio']:.0f}x | {m['all']:.0f} |")
    print(f"(n = 32, m = 2, the simulator's default horizon; medians of {args.repeats} runs; labels equal bit for bit)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
