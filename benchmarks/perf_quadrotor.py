"""Quadrotor fast labelling: agreement with PyBullet and labels per second (issue figures).

Run: ``python -m benchmarks.perf_quadrotor [--rooms 4] [--branches 100]``.

For states sampled as the dataset samples them and uniform random controls (2 s, 8 points),
each branch is propagated by the numpy integrator and checked analytically, and simulated in
PyBullet (with real contact response).  Verdicts are compared at the same 8 path states, and
against PyBullet's contact at any physics step; trajectories are compared up to the first
contact.  Then labels/s of the estimator (n = 32, m = 2, t = 2 s) in one process.
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from rmm_envs.risk import RiskEstimator
from rmm_envs.systems.quadrotor.body import QUADROTOR
from rmm_envs.systems.quadrotor.pybullet_body import push_body


def compare(env, states, controls):
    scene = env.risk_scene()
    paths = scene.propagate(states, controls, 2.0, 8)
    ours = scene.collision.states_failed(paths.reshape(-1, 13)).reshape(-1, 8)
    pb8 = np.zeros_like(ours)
    pb_any = np.zeros(len(states), dtype=bool)
    max_err = np.zeros(len(states))
    for i, (s, u) in enumerate(zip(states, controls, strict=True)):  # one control per state
        env.set_state(s)
        touched = False
        for seg in range(7):
            touched |= push_body(env.p, env.client, env.body, u, 69)[1]
            pb8[i, seg + 1] = env.in_contact()
            if not touched:
                max_err[i] = max(max_err[i], np.linalg.norm(env.get_state()[:3] - paths[i, seg + 1, :3]))
        pb_any[i] = touched
        env.set_state(s)
        pb8[i, 0] = env.in_contact()
    return ours, pb8, pb_any, max_err


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rooms", type=int, default=4)
    ap.add_argument("--branches", type=int, default=100)
    args = ap.parse_args(argv)
    env = gym.make("QuadrotorRoom-v0").unwrapped
    agree8, agree_any, errs, fails = [], [], [], []
    for seed in range(args.rooms):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        states = env.sample_states(rng, args.branches)
        controls = env.risk_scene().sample_controls(rng, args.branches)
        ours, pb8, pb_any, err = compare(env, states, controls)
        agree8.append(np.mean(ours.any(1) == pb8.any(1)))
        agree_any.append(np.mean(ours.any(1) == pb_any))
        errs.append(err)
        fails.append(pb_any.mean())
    print(f"quadrotor branches vs PyBullet ({args.rooms} rooms x {args.branches} branches, 2 s, 8 points):")
    print(
        f"  vs PyBullet's contact at any physics step (what the env terminates on): {100 * np.mean(agree_any):.1f}% "
        f"of branches agree (target >= 98%); PyBullet fails {100 * np.mean(fails):.0f}% of branches"
    )
    print(
        f"  (checked at the same 8 states only: {100 * np.mean(agree8):.1f}%, lower because PyBullet's contact response "
        "moves the body after a contact, so later states differ)"
    )
    e = np.concatenate(errs)
    print(f"  position error before the first contact: median {np.median(e):.1e} m, max {e.max():.1e} m")
    # env steps per second: stepping alone, and with the resets that rebuild a room
    hover = np.array([QUADROTOR.hover_thrust, 0.0, 0.0, 0.0], np.float32)
    n, t_all, t_step, seed = 0, time.perf_counter(), 0.0, 0
    while n < 3000:
        env.reset(seed=seed)
        seed += 1
        t0 = time.perf_counter()
        while True:
            _, _, te, tr, _ = env.step(hover)
            n += 1
            if te or tr:
                break
        t_step += time.perf_counter() - t0
    print(
        f"QuadrotorRoom-v0 steps/s (hover thrust): {n / t_step:.0f} stepping (target >= 2,000), "
        f"{n / (time.perf_counter() - t_all):.0f} including {seed} resets (each generates and builds a room)"
    )
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    states = env.sample_states(rng, 64)
    est = RiskEstimator(env.risk_scene())
    t0 = time.perf_counter()
    est.estimate(states, rng)
    print(f"labels/s, n=32, m=2, t=2 s, one process: {64 / (time.perf_counter() - t0):.1f} (target >= 20)")


if __name__ == "__main__":
    main()
