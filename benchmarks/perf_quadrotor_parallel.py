"""Quadrotor parallel-autonomy env performance: steps/s with the inactive guardian, one process.

Run: ``python -m benchmarks.perf_quadrotor_parallel [--episodes 20] [--repeats 3]``.  Steps
``QuadrotorRoomParallel-v0`` (fixed 1 ms clock, so the simulated intervals do not depend on
the machine: 0.11 s, 26-27 PyBullet steps each) with the pilot in control, resets included
(perf_env's loop), and ``Dubins3DMazeParallel-v0`` the same way in the same run: the ratio
between the two is what a shared machine can compare (issue target: >= 1,500 steps/s for the
quadrotor env).  Then the parts: a reset (room generation, PyBullet build), stepping alone,
and one physics step's PyBullet calls and controller.
"""

from __future__ import annotations

import argparse
import statistics
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from benchmarks._timing import fmt_us, median_time
from benchmarks.perf_env import steps_per_second as _steps_per_second
from rmm_envs.systems.quadrotor.control import command_wrench
from rmm_envs.systems.quadrotor.rooms import generate_room

QUAD = "QuadrotorRoomParallel-v0"
BASELINE = "Dubins3DMazeParallel-v0"


def steps_per_second(env_id: str, episodes: int, repeats: int) -> list[float]:
    return _steps_per_second(env_id, episodes, repeats, clock="fixed:1")


def stepping_only(episodes: int) -> tuple[float, float]:
    """(steps/s excluding resets, mean reset seconds) over ``episodes`` seeded episodes."""
    env = gym.make(QUAD, clock="fixed:1")
    inactive = env.action_space.inactive()
    n, t_step, t_reset = 0, 0.0, 0.0
    for ep in range(episodes):
        t0 = time.perf_counter()
        env.reset(seed=ep)
        t1 = time.perf_counter()
        done = False
        while not done:
            _, _, te, tr, _ = env.step(inactive)
            n += 1
            done = te or tr
        t_reset += t1 - t0
        t_step += time.perf_counter() - t1
    env.close()
    return n / t_step, t_reset / episodes


def parts() -> dict[str, float]:
    env = gym.make("QuadrotorRoomGuarded-v0").unwrapped
    env.reset(seed=0)
    p, c, b = env.p, env.client, env.body
    s = env.get_state()
    cmd, w, k = np.array([1.0, 0.0, 0.0, 0.0]), np.empty(4), env.controller.packed
    rng = np.random.default_rng(0)
    out = {
        "generate_room": median_time(lambda: generate_room(rng), repeats=5),
        "build the room in PyBullet": median_time(lambda: env._build(env.room), repeats=5),
    }
    env.reset(seed=0)
    p, c, b = env.p, env.client, env.body

    def physics_step():
        p.applyExternalForce(b, -1, (0.0, 0.0, 4.905), (0.0, 0.0, 0.0), p.LINK_FRAME, physicsClientId=c)
        p.applyExternalTorque(b, -1, (0.0, 0.0, 0.0), p.LINK_FRAME, physicsClientId=c)
        p.stepSimulation(physicsClientId=c)

    out.update(
        {
            "controller (compiled, one state)": median_time(lambda: command_wrench(s, cmd, k, w), number=1000),
            "apply thrust and moments, stepSimulation": median_time(physics_step, number=200),
            "getContactPoints": median_time(lambda: p.getContactPoints(bodyA=b, physicsClientId=c), number=500),
            "get the state": median_time(env.get_state, number=500),
            "10 rays": median_time(env.rays, number=200),
            "room clearance (once per step)": median_time(lambda: env.scene.collision.clearance(s[:3]), number=200),
        }
    )
    env.close()
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    rates = {}
    for env_id in (QUAD, BASELINE):
        rates[env_id] = statistics.median(steps_per_second(env_id, args.episodes, args.repeats))
        print(
            f"{env_id:26s} inactive guardian, one process, resets included: {rates[env_id]:8.0f} steps/s "
            f"(median of {args.repeats} runs of {args.episodes} episodes)"
        )
    print(f"ratio quadrotor / maze (same run): {rates[QUAD] / rates[BASELINE]:.2f}")
    rate, reset = stepping_only(args.episodes)
    print(f"{QUAD}: {rate:.0f} steps/s stepping alone; a reset takes {1e3 * reset:.1f} ms")
    for name, t in parts().items():
        print(f"  {name:44s} {fmt_us(t)}")


if __name__ == "__main__":
    main()
