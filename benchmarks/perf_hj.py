"""HJ reachability performance and convergence (issue figures).

Run: ``python -m benchmarks.perf_hj [--quick] [--solve-only]``.

* solve time and peak memory on the default grid (64 x 64 x 32 x 32, 4 s, five obstacles):
  the default scheme (ENO2 + TVD-RK3, compiled; median of 3, one thread and all threads)
  against the first-order RK2 kernel (``hj-paper``'s scheme) in the same run, and against the
  numpy implementation of the default scheme (once).  One-thread solves also report the
  process's CPU time: on a loaded machine the wall time counts waits for a core, the CPU time
  does not (read it, or the ratios, there);  ``--solve-only`` stops after the compiled solves;
* online decision time (interpolation of V and its gradient), median over many states;
* convergence of the unsafe set (V <= 0) as the grid is refined: the unsafe fraction of a
  fixed set of probe states for several grids, against the finest;
* ``--quadrotor N``: instead of all the above, the quadrotor ``hj``'s solves
  (:mod:`rmm_guardians.hj.quadrotor`, one or two values per leg of the route) on the rooms of the first ``N``
  episodes of ``rmm-bench --env QuadrotorRoomParallel-v0 --seed 0``, one thread, no cache: grid
  sizes and solve times per value and per episode, the guardian's decision time on those
  episodes' starts, and the CPU time of a climb plan (:mod:`rmm_guardians.hj.quadrotor_climb`) along
  each leg of their routes, from rest;
* ``--first-use``: instead of all the above, what a fresh install pays once: a fresh
  interpreter's first solve of each scheme (a small grid, so the time is numba compiling the
  kernels), with an empty numba cache and then again with the cache that run wrote.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import time

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.dubins4d.dynamics import DYNAMICS_NAME, Dubins4D
from rmm_envs.systems.dubins4d.env import CONTROLS
from rmm_guardians.hj._kernels import set_threads
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.guardian import HJGuardian, default_grid, obstacle_target
from rmm_guardians.hj.solver import solve_brt

OBSTACLES = np.array([[0.0, 0.0, 3.0], [6.0, 5.0, 2.5], [-7.0, 3.0, 4.0], [4.0, -8.0, 2.0], [-5.0, -6.0, 3.0]])


_FIRST_USE = """
import json, os, sys, time
os.environ["NUMBA_CACHE_DIR"] = sys.argv[1]  # before numba is imported
t0 = time.perf_counter()
import numpy as np
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.guardian import default_grid, obstacle_target
from rmm_guardians.hj.solver import solve_brt
out = {"import": time.perf_counter() - t0}
grid = default_grid((8, 8, 8, 8))
for order in (2, 1):
    t = time.perf_counter()
    solve_brt(grid, Dubins4DHJ(), obstacle_target(grid, np.array([[0.0, 0.0, 3.0]])), 0.5, order=order, backend="numba")
    out[f"order {order}"] = time.perf_counter() - t
print(json.dumps(out))
"""


def first_use() -> None:
    """Fresh interpreters' first solves: numba compiling the kernels (empty cache), then loading them."""
    import json
    import subprocess
    import sys
    import tempfile

    with tempfile.TemporaryDirectory() as cache:
        print("first solves in a fresh interpreter (8^4 grid, 0.5 s: the time is numba's), seconds:")
        for label in ("empty numba cache", "cache of the run above"):
            got = json.loads(
                subprocess.run(
                    [sys.executable, "-c", _FIRST_USE, cache], check=True, capture_output=True, text=True
                ).stdout.splitlines()[-1]
            )
            print(f"  {label}: " + ", ".join(f"{k} {v:.2f}" for k, v in got.items()))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="skip the finest grid of the convergence study")
    ap.add_argument("--solve-only", action="store_true", help="only the compiled solves on the default grid")
    ap.add_argument(
        "--quadrotor", type=int, default=0, metavar="N", help="time the quadrotor hj's solves on N rooms instead"
    )
    ap.add_argument("--first-use", action="store_true", help="time a fresh interpreter's first solves, cold and cached")
    args = ap.parse_args(argv)
    if args.first_use:
        return first_use()
    if args.quadrotor:
        return quadrotor(args.quadrotor)
    grid = default_grid()
    target = obstacle_target(grid, OBSTACLES)
    for order in (1, 2):  # compile / load both kernels
        solve_brt(
            default_grid((8, 8, 8, 8)),
            Dubins4DHJ(),
            obstacle_target(default_grid((8, 8, 8, 8)), OBSTACLES),
            0.5,
            order=order,
        )
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    timings, cpu = {}, {}
    for label, threads, order, rk in (
        ("ENO2/RK3, 1 thread", 1, 2, 3),
        ("first order/RK2, 1 thread", 1, 1, 2),
        (f"ENO2/RK3, {os.cpu_count()} threads", None, 2, 3),
    ):
        set_threads(threads)
        runs, cpu_runs = [], []
        for _ in range(3):
            c0 = time.process_time()
            t0 = time.perf_counter()
            V, info = solve_brt(grid, Dubins4DHJ(), target, 4.0, order=order, rk=rk, backend="numba")
            runs.append(time.perf_counter() - t0)
            cpu_runs.append(time.process_time() - c0)
        timings[label] = statistics.median(runs)
        if threads == 1:
            cpu[label] = statistics.median(cpu_runs)
        if order == 2:
            V2, info2 = V, info
    set_threads(None)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    if args.solve_only:
        for label, t in timings.items():
            print(f"  {label}: median wall {t:.2f} s" + (f", CPU {cpu[label]:.2f} s" if label in cpu else ""))
        print(f"  peak RSS {rss / 1024:.0f} MB; target: ENO2/RK3 <= 3 s on one core")
        return
    t0 = time.perf_counter()
    V_np, _ = solve_brt(grid, Dubins4DHJ(), target, 4.0, backend="numpy")
    t_np = time.perf_counter() - t0
    print(
        f"HJ solve, default grid {grid.shape}, 5 obstacles, 4 s horizon ({info2['steps']} steps of {info2['dt']:.3f} s):"
    )
    for label, t in timings.items():
        print(
            f"  {label}: median wall {t:.2f} s"
            + (f", CPU {cpu[label]:.2f} s" if label in cpu else "")
            + f" ({t_np / t:.1f}x the numpy path)"
        )
    ratio = timings["ENO2/RK3, 1 thread"] / timings["first order/RK2, 1 thread"]
    print(f"  ENO2/RK3 / first order on one thread, same run: {ratio:.2f}x (target: ENO2 <= 3 s on one core)")
    print(f"  numpy path of ENO2/RK3 (same run): {t_np:.1f} s; max |V_numba - V_numpy| = {np.abs(V2 - V_np).max():.1e}")
    print(
        f"  peak RSS of the compiled solves {rss / 1024:.0f} MB (before: {rss0 / 1024:.0f} MB); targets <= 30 s and <= 1.5 GB"
    )

    box = {"obstacles": OBSTACLES, "goal": np.array([9.0, 9.0, 0.5]), "state": np.zeros(4)}
    g = HJGuardian(cache=False)
    g.reset(
        seed=0,
        privileged=lambda: box,
        action_space=GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, dynamics_name=DYNAMICS_NAME),
    )
    rng = np.random.default_rng(0)
    states = np.column_stack(
        [
            rng.uniform(-12, 12, 2000),
            rng.uniform(-12, 12, 2000),
            rng.uniform(-np.pi, np.pi, 2000),
            rng.uniform(0, 2, 2000),
        ]
    )
    times = []
    for s in states:
        box["state"] = s
        t = time.perf_counter()
        g.act(None, {})
        times.append(time.perf_counter() - t)
    print(
        f"online decision: median {statistics.median(times) * 1e6:.1f} us, "
        f"p90 {np.quantile(times, 0.9) * 1e6:.1f} us (target <= 50 us)"
    )

    print("convergence of the unsafe set (fraction of 20,000 probe states with V <= 0):")
    probes = np.column_stack(
        [
            rng.uniform(-12, 12, 20000),
            rng.uniform(-12, 12, 20000),
            rng.uniform(-np.pi, np.pi, 20000),
            rng.uniform(0, 2, 20000),
        ]
    )
    sizes = [(32, 32, 16, 16), (48, 48, 24, 24), (64, 64, 32, 32)] + ([] if args.quick else [(96, 96, 48, 32)])
    verdicts = {}
    for n in sizes:
        gr = default_grid(n)
        t0 = time.perf_counter()
        Vn, _ = solve_brt(gr, Dubins4DHJ(), obstacle_target(gr, OBSTACLES), 4.0)
        unsafe = np.array([gr.interp(Vn, p) <= 0 for p in probes])
        verdicts[n] = unsafe
        print(f"  grid {n}: unsafe fraction {unsafe.mean():.4f} ({time.perf_counter() - t0:.1f} s)")
    finest = verdicts[sizes[-1]]
    for n in sizes[:-1]:
        print(
            f"  grid {n}: verdicts differ from the finest grid on {np.mean(verdicts[n] != finest) * 100:.2f}% of probes"
        )


def quadrotor(n: int) -> None:
    """The quadrotor ``hj``'s solve times (see the module docstring)."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401
    from rmm_bench.runner import episode_seed
    from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian

    env = gym.make("QuadrotorRoomParallel-v0", clock="fixed:1")
    g = QuadrotorHJGuardian(cache=False, threads=1)
    set_threads(1)
    legs, episodes, nodes, decisions, plans, found = [], [], [], [], [], 0
    for i in range(n):
        seed = episode_seed(0, i)
        obs, info = env.reset(seed=seed)
        c0 = time.process_time()
        g.reset(
            seed=seed,
            observation_space=env.observation_space,
            action_space=env.action_space,
            privileged=env.unwrapped.privileged,
        )
        episodes.append(time.process_time() - c0)
        values = [v for leg in g._legs for v in leg]
        legs += [g.solve_seconds / len(values)] * len(values)
        nodes += [int(np.prod(grid.shape)) for _, grid, _, _ in values]
        t = time.perf_counter()
        g.act(obs, info)
        decisions.append(time.perf_counter() - t)
        route = [g._privileged()["state"][:3], *g.waypoints]
        for a, b in zip(route[:-1], route[1:], strict=True):  # consecutive waypoints
            c0 = time.process_time()
            found += g._climb.plan(a[:2], a[:2], (0.0, 0.0), float(a[2]), b) is not None
            plans.append(time.process_time() - c0)
    print(
        f"quadrotor hj, {n} rooms of seed 0 (grid {g.spacing} m x {g.n_heading} headings x {g.n_speed} speeds, "
        f"{g.horizon} s, ENO2/RK3, one thread, no cache):"
    )
    print(f"  nodes per value: median {statistics.median(nodes):,.0f} (range {min(nodes):,}-{max(nodes):,})")
    print(
        f"  reset (all legs' solves and targets), CPU: median {statistics.median(episodes):.2f} s, "
        f"range {min(episodes):.2f}-{max(episodes):.2f} s; solve wall per value: median {statistics.median(legs):.2f} s"
    )
    print(f"  first decision: median {statistics.median(decisions) * 1e6:.0f} us")
    print(
        f"  climb plan along each leg from rest, CPU: median {statistics.median(plans) * 1e3:.1f} ms, "
        f"at most {max(plans) * 1e3:.1f} ms ({len(plans)} legs, {found} clear)"
    )


if __name__ == "__main__":
    main()
