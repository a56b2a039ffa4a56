"""Steps per second: the native vector env against the single env, and the single env against
its earlier OSQP driver, all measured in one run.

Run: ``python -m benchmarks.perf_vector [--num-envs 256] [--repeats 7] [--no-pin]``.

Three workloads, the driver in control in every world (the inactive guardian: the env's own
work, no agent), interleaved round by round so that they share the machine's load:

* ``single``: ``gym.make("Dubins4DGuarded-v0")`` (the closed-form driver), whole episodes from
  seeds ``0, 1, ...``, one ``step`` per call;
* ``single-osqp``: the same env with ``driver_solver="osqp"``, the driver's QP solved by OSQP as
  before the closed form (the baseline of the single env's speed-up);
* ``vector``: ``gym.make_vec(..., num_envs=N, vectorization_mode="vector_entry_point")``, one
  ``step`` advancing ``N`` worlds, autoresets included; its rate counts sub-env steps.

Each repeat times a fixed amount of work (about ``--single-steps`` env steps, or ``--vector-steps``
vector steps); the figures are medians over repeats and the ratios are of medians.  The process
is pinned to one core unless ``--no-pin`` (numba and numpy run single-threaded here anyway).
The machine's load average is printed before and after: on a loaded machine the absolute
rates drop, the ratios much less.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401

ID = "Dubins4DGuarded-v0"


def _inactive(n: int | None = None) -> dict:
    one = gym.make("Dubins4DGuarded-v0").action_space.inactive()
    if n is None:
        return one
    return {k: np.zeros((n, 1), np.float32) if np.ndim(v) else np.zeros(n, np.int64) for k, v in one.items()}


class SingleRunner:
    """Whole episodes of the single env until at least ``steps`` steps; returns steps/s."""

    def __init__(self, steps: int, **kwargs) -> None:
        self.env = gym.make(ID, **kwargs)
        self.steps = steps
        self.seed = 0
        self.env.reset(seed=0)
        self.env.step(_inactive())  # load the compiled paths before timing

    def __call__(self) -> float:
        env, a, n = self.env, _inactive(), 0
        t0 = time.perf_counter()
        while n < self.steps:
            env.reset(seed=self.seed)
            self.seed += 1
            done = False
            while not done:
                _, _, te, tr, _ = env.step(a)
                n += 1
                done = te or tr
        return n / (time.perf_counter() - t0)


class VectorRunner:
    """``steps`` calls of the vector env's ``step``; returns sub-env steps/s."""

    def __init__(self, num_envs: int, steps: int) -> None:
        self.env = gym.make_vec(ID, num_envs=num_envs, vectorization_mode="vector_entry_point")
        self.steps, self.n = steps, num_envs
        self.env.reset(seed=0)
        self.a = _inactive(num_envs)
        for _ in range(3):
            self.env.step(self.a)

    def __call__(self) -> float:
        env, a = self.env, self.a
        t0 = time.perf_counter()
        for _ in range(self.steps):
            env.step(a)
        return self.steps * self.n / (time.perf_counter() - t0)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--num-envs", type=int, default=256)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--single-steps", type=int, default=3000)
    p.add_argument("--vector-steps", type=int, default=100)
    p.add_argument("--no-pin", action="store_true", help="do not pin the process to one core")
    args = p.parse_args(argv)
    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        core = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {core})
        print(f"pinned to core {core}")
    load0 = os.getloadavg()
    runners = {
        "single": SingleRunner(args.single_steps),
        "single-osqp": SingleRunner(args.single_steps, driver_solver="osqp"),
        "vector": VectorRunner(args.num_envs, args.vector_steps),
    }
    rates: dict[str, list[float]] = {k: [] for k in runners}
    for _ in range(args.repeats):  # interleaved: every workload sees the same load
        for k, run in runners.items():
            rates[k].append(run())
    load1 = os.getloadavg()
    med = {k: statistics.median(v) for k, v in rates.items()}
    print(
        f"load average (1, 5, 15 min) before {load0[0]:.1f} {load0[1]:.1f} {load0[2]:.1f}, "
        f"after {load1[0]:.1f} {load1[1]:.1f} {load1[2]:.1f}; {os.cpu_count()} cores"
    )
    print(f"steps/s, median (min-max) of {args.repeats} interleaved repeats, the driver in control:")
    labels = {
        "single": "single env, closed-form driver",
        "single-osqp": "single env, OSQP driver (before)",
        "vector": f"vector env, {args.num_envs} sub-envs",
    }
    for k, v in rates.items():
        print(f"  {labels[k]:34s} {med[k]:10.0f}  ({min(v):.0f}-{max(v):.0f})")
    r_vec = med["vector"] / med["single"]
    r_single = med["single"] / med["single-osqp"]
    print(f"vector / single: {r_vec:.1f}x (target >= 20x); single closed form / OSQP: {r_single:.2f}x (target >= 2x)")
    return {
        "median": med,
        "rates": rates,
        "load": (load0, load1),
        "vector_over_single": r_vec,
        "single_over_osqp": r_single,
    }


if __name__ == "__main__":
    main()
