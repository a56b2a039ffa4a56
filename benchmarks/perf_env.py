"""Dubins4D environment performance (issue figures: steps/s, rays, batched collision).

Run: ``python -m benchmarks.perf_env``.  Prints medians over repeats and ratios against
baselines measured in the same run (an ``odeint`` propagation per step, as the original did,
the numpy array code of the same formulas, and a Python loop over rays and circles).  The vector
env, and the single env against its earlier OSQP driver: ``benchmarks/perf_vector.py``.
"""

from __future__ import annotations

import math
import statistics
import time

import gymnasium as gym
import numpy as np
from scipy.integrate import odeint

import rmm_envs  # noqa: F401
from benchmarks._timing import fmt_us, median_time
from rmm_envs.systems.dubins4d.circles import CircleWorld, points_in_circles, ray_cast, ray_cast_numpy
from rmm_envs.systems.dubins4d.driver import CLFDriver
from rmm_envs.systems.dubins4d.dynamics import Dubins4D


def steps_per_second(
    env_id: str = "Dubins4DGuarded-v0", episodes: int = 10, repeats: int = 5, **env_kwargs
) -> list[float]:
    """Steps per second of ``env_id`` driven by the inactive guardian, one value per repeat
    (the same ``episodes`` seeded episodes each time)."""
    env = gym.make(env_id, **env_kwargs)
    inactive = env.action_space.inactive()
    env.reset(seed=0)
    env.step(inactive)  # load the compiled paths before timing
    rates = []
    for _ in range(repeats):
        n = 0
        t0 = time.perf_counter()
        for ep in range(episodes):
            env.reset(seed=ep)
            done = False
            while not done:
                _, _, te, tr, _ = env.step(inactive)
                n += 1
                done = te or tr
        rates.append(n / (time.perf_counter() - t0))
    env.close()
    return rates


def profile_step() -> dict[str, float]:
    env = gym.make("Dubins4DGuarded-v0").unwrapped
    env.reset(seed=0)
    st = env.true_state
    goal = env.scene.goal
    sys_ = env.dynamics
    u = env.driver.control(st, goal)
    osqp_driver = CLFDriver(
        env.driver.lim[:2], env.driver.lim[2:4], env.driver.lim[4:], env.driver.params, solver="osqp"
    )
    parts = {
        "driver QP (closed form)": median_time(lambda: env.driver.control(st, goal), number=500),
        "driver QP (OSQP)": median_time(lambda: osqp_driver.control(st, goal), number=500),
        "propagate 16 pts": median_time(lambda: sys_.propagate(st[None], u[None], 0.1, 16), number=500),
        "observe (rays)": median_time(lambda: env.scene.observe(st[None], 0.0), number=500),
    }
    return parts


def _odeint_step(state, u):
    def rhs(z, t):
        x, y, th, v = z
        dv = u[1]
        if (dv < 0 and v < 1e-3) or (dv > 0 and v > 2 - 1e-3):
            dv = 0.0
        return [v * math.cos(th), v * math.sin(th), u[0], dv]

    return odeint(rhs, state, np.linspace(0, 0.1, 16))


def _loop_rays(x, y, th, circles, n=12, L=10.0):
    out = []
    for i in range(n):
        a = th + 2 * math.pi * i / n
        dx, dy = math.cos(a), math.sin(a)
        best = L
        for cx, cy, r in circles:
            fx, fy = cx - x, cy - y
            cc = fx * fx + fy * fy - r * r
            if cc <= 0:
                best = 0.0
                continue
            b = dx * fx + dy * fy
            disc = b * b - cc
            if disc >= 0 and b - math.sqrt(disc) >= 0:
                best = min(best, b - math.sqrt(disc))
        out.append(best)
    return out


def main() -> None:
    rng = np.random.default_rng(0)
    circles = CircleWorld.generate(rng)
    print("Dubins4DGuarded-v0, driver in control (inactive guardian), one process")
    rates = steps_per_second()
    print(
        f"  steps/s: median {statistics.median(rates):8.0f} over {len(rates)} runs "
        f"(min {min(rates):.0f}, max {max(rates):.0f}); target >= 5,000"
    )
    parts = profile_step()
    for k, v in parts.items():
        print(f"  {k:24s} {fmt_us(v)} per step")
    st = np.array([0.5, -1.0, 0.3, 1.2])
    sysm, u, times = Dubins4D(), np.array([[0.1, 0.2]]), np.linspace(0.0, 0.1, 16)
    t_ours = median_time(lambda: sysm.propagate(st[None], u, 0.1, 16), number=300)
    t_np = median_time(lambda: sysm._states_at_numpy(st[None], u, times), number=300)
    t_ode = median_time(lambda: _odeint_step(st, (0.1, 0.2)), number=300)
    print(
        f"  propagation, one 16-point path: ours (compiled) {fmt_us(t_ours)}, same formulas as numpy array code "
        f"{fmt_us(t_np)}, odeint (original) {fmt_us(t_ode)}: {t_ode / t_ours:.1f}x odeint"
    )

    print("Rays (12 x 10 m, 5 circles), one state")
    o, h = np.array([[0.5, -1.0]]), np.array([0.3])
    t_ray = median_time(lambda: ray_cast(o, h, circles), number=2000)
    t_loop = median_time(lambda: _loop_rays(0.5, -1.0, 0.3, circles), number=2000)
    t_ray_np = median_time(lambda: ray_cast_numpy(o, h, circles, 12, 10.0), number=2000)
    print(
        f"  ours (compiled for a few states) {fmt_us(t_ray)} (target <= 20 us); the same formulas as numpy "
        f"array code {fmt_us(t_ray_np)}; python loop {fmt_us(t_loop)}"
    )
    pts = rng.uniform(-10, 10, (10_000, 2))
    t_pts = median_time(lambda: points_in_circles(pts, circles), number=50)
    print(f"Point-in-circle, 10,000 points x 5 circles: {t_pts * 1e3:.3f} ms (target <= 1 ms)")
    rays_batch = median_time(lambda: ray_cast(pts, np.zeros(10_000), circles), number=5)
    print(f"Rays for 10,000 states: {rays_batch * 1e3:.2f} ms ({rays_batch / 1e4 * 1e6:.2f} us/state)")


if __name__ == "__main__":
    main()
