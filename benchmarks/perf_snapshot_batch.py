"""Labels/s of a simulator of your own, batched (its ``step_batch`` hook) against step by step
(the snapshot protocol's ``set_state`` and ``step``, one branch at a time), measured in the same
run on the same states with the same tree and checked to be the same labels, bit for bit.

Run: ``python -m benchmarks.perf_snapshot_batch [--labels 256] [--loop-labels 32] [--repeats 5]
[--min-run 0.02]``.

Simulators: the tutorial's ``CartWall`` (docs/examples/own_simulator_wall.py: a cart before a
wall, the cheapest possible step) and ``PointRays`` (docs/examples/own_simulator_rays.py: a point
robot among three circles, the kind of simulator a user brings).  For each: the same estimator
(``n = 32, m = 2``, the simulator's default horizon) labels ``--loop-labels`` states step by step
and batched, on one tree of controls drawn once, and every output (risk, minimum-risk control and
its hold, leaf counts) is checked equal bit for bit; the ratio is labels/s batched over step by
step on those states, each a median of ``--repeats`` runs, in wall time and in this process's
CPU time (what other jobs on a shared machine take from it does not count).  Each way labels the
states once untimed first (compiled helpers load on a process's first label), and the runs
alternate, one step by step then one batched, so both see the same load; a batched run labels
the states again until it has taken at least ``--min-run`` seconds (one pass takes about a
millisecond, below a loaded machine's scheduling noise).  The batched labels/s over ``--labels``
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


def _run(estimator, states, controls, min_seconds: float) -> tuple[float, float]:
    """Labels/s of one run in wall time and in this process's CPU time: the states labelled
    (again) until ``min_seconds`` of wall time have passed."""
    passes, t0, c0 = 0, time.perf_counter(), time.process_time()
    while True:
        estimator.estimate(states, controls=controls)
        passes += 1
        elapsed = time.perf_counter() - t0
        if elapsed >= min_seconds:
            n = passes * states.shape[0]
            return n / elapsed, n / max(time.process_time() - c0, 1e-9)


def _bits(result) -> bytes:
    return b"".join(
        np.ascontiguousarray(a).tobytes()
        for a in (result.risk, result.min_risk_ctrl, result.min_risk_ctrl_dur, result.n_leaves)
    )


def measure(cls, labels: int, loop_labels: int, repeats: int, min_run: float = 0.02, seed: int = 0) -> dict:
    sim = cls()
    states = np.asarray(sim.sample_states(np.random.default_rng(seed), labels), dtype=float)
    states = states[~sim.state_failed(states)]
    few = states[:loop_labels]
    kw = dict(branches=32, depth=2, horizon=cls.default_horizon)
    fast = RiskEstimator(SnapshotScene(cls(), default_horizon=cls.default_horizon), **kw)
    slow = RiskEstimator(SnapshotScene(_step_by_step(cls)(), default_horizon=cls.default_horizon), **kw)
    controls = fast.draw_controls(np.random.default_rng(seed), few.shape[0])
    if _bits(fast.estimate(few, controls=controls)) != _bits(slow.estimate(few, controls=controls)):
        raise AssertionError(f"{cls.__name__}: batched labels differ from step-by-step ones")
    slow_runs, fast_runs = [], []
    for _ in range(repeats):  # alternating: both ways under the same load
        slow_runs.append(_run(slow, few, controls, 0.0))
        fast_runs.append(_run(fast, few, controls, min_run))
    all_controls = fast.draw_controls(np.random.default_rng(seed), states.shape[0])
    fast.estimate(states, controls=all_controls)
    all_rate = statistics.median(_run(fast, states, all_controls, min_run)[0] for _ in range(repeats))
    (slow_rate, slow_cpu), (fast_rate, fast_cpu) = (
        [statistics.median(r[i] for r in runs) for i in (0, 1)] for runs in (slow_runs, fast_runs)
    )
    return {
        "step": slow_rate,
        "batched": fast_rate,
        "ratio": fast_rate / slow_rate,
        "cpu_ratio": fast_cpu / slow_cpu,
        "all": all_rate,
        "n": len(few),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--labels", type=int, default=256, help="states labelled batched for the overall rate")
    ap.add_argument("--loop-labels", type=int, default=32, help="states labelled both ways for the ratio")
    ap.add_argument("--repeats", type=int, default=5, help="runs per median")
    ap.add_argument("--min-run", type=float, default=0.02, help="seconds a batched run lasts at least")
    args = ap.parse_args(argv)
    print(
        "| simulator | states | step by step [labels/s] | batched [labels/s] | ratio | ratio in CPU time "
        "| batched, all states [labels/s] |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, cls in _simulators().items():
        m = measure(cls, args.labels, args.loop_labels, args.repeats, args.min_run)
        print(
            f"| {name} | {m['n']} | {m['step']:.0f} | {m['batched']:.0f} | {m['ratio']:.0f}x | {m['cpu_ratio']:.0f}x "
            f"| {m['all']:.0f} |"
        )
    print(
        f"(n = 32, m = 2, the simulator's default horizon; medians of {args.repeats} alternating runs, wall time "
        "unless said; labels equal bit for bit)"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
