"""Maze parallel-autonomy env performance: steps/s with the inactive guardian, one process.

Run: ``python -m benchmarks.perf_maze``.  Steps ``Dubins3DMazeParallel-v0`` (fixed 1 ms clock,
so the simulated intervals do not depend on the machine) with the driver in control, resets
included, and ``Dubins4DParallel-v0`` the same way in the same run: the ratio between the two
is what a shared machine can compare (issue target: >= 3,000 steps/s for the maze env).  Also
times one step's parts: the compiled one-car kernels against the numpy ``Maze`` queries they
replace (same values, checked by the tests).
"""

from __future__ import annotations

import argparse
import statistics

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401
from benchmarks._timing import fmt_us, median_time
from benchmarks.perf_env import steps_per_second as _steps_per_second
from rmm_envs.systems.dubins4d.dynamics import SERIES_COEFFICIENTS
from rmm_envs.systems.maze.maze_kernels import dubins_path, maze_path_hit, maze_rays


def steps_per_second(env_id: str, episodes: int, repeats: int) -> list[float]:
    """Steps per second with the inactive guardian under a fixed 1 ms clock (perf_env's loop)."""
    return _steps_per_second(env_id, episodes, repeats, clock="fixed:1")


def parts() -> dict[str, float]:
    env = gym.make("Dubins3DMazeGuarded-v0").unwrapped
    env.reset(seed=0)
    m = env.scene.maze
    st = env.true_state
    path = env.dynamics.propagate(st[None], np.array([[0.1]]), 0.11, 8)
    out = np.empty(8)
    return {
        "rays, compiled": median_time(
            lambda: maze_rays(m.walls, m.half, m.width, m.height, st[0], st[1], st[2], 8, out), number=500
        ),
        "rays, numpy Maze.rays": median_time(lambda: m.rays(st[None], 8), number=100),
        "path contact, compiled": median_time(
            lambda: maze_path_hit(m.walls, m.half, m.width, m.height, path[0]), number=500
        ),
        "path contact, numpy Maze.paths_hit": median_time(lambda: m.paths_hit(path), number=100),
        "path, compiled": median_time(
            lambda: dubins_path(st[0], st[1], st[2], 10.0, 0.1, 0.11, np.empty((8, 3)), SERIES_COEFFICIENTS), number=500
        ),
        "path, numpy Dubins3D.propagate": median_time(
            lambda: env.dynamics.propagate(st[None], np.array([[0.1]]), 0.11, 8), number=100
        ),
        "driver": median_time(lambda: env.driver.control(st), number=500),
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args(argv)
    rates = {}
    for env_id in ("Dubins3DMazeParallel-v0", "Dubins4DParallel-v0"):
        rates[env_id] = statistics.median(steps_per_second(env_id, args.episodes, args.repeats))
        print(
            f"{env_id:26s} inactive guardian, one process: {rates[env_id]:8.0f} steps/s (median of {args.repeats} runs)"
        )
    print(f"ratio maze / Dubins4D (same run): {rates['Dubins3DMazeParallel-v0'] / rates['Dubins4DParallel-v0']:.2f}")
    for k, v in parts().items():
        print(f"  {k:36s} {fmt_us(v)}")


if __name__ == "__main__":
    main()
