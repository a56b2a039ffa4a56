"""What disturbances cost per env step (issue 52's targets: off, no measurable cost; on, at most
10% more per single-env step and 25% per vector-env sub-env step).

Run: ``python -m benchmarks.perf_disturbances [--repeats 5] [--against OTHER_PYTHON]``.  Prints
the median time per step of ``Dubins4DGuarded-v0`` driven by its driver, undisturbed and under
each kind (and all at once), and the same per sub-env of its vector env (16 sub-envs), with
ratios to the undisturbed step measured in the same run.  ``--against`` names the Python of
another checkout (e.g. one at the commit before disturbances, with its own virtual environment):
the undisturbed single-env step is then measured there and here alternately, each repeat, and
the ratio of the medians printed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401  (registers the envs)

ENV = "Dubins4DGuarded-v0"
KINDS = {
    "obs-noise": "obs-noise=0.1",
    "ray-dropout": "ray-dropout=0.05",
    "act-noise": "act-noise=0.1",
    "act-delay": "act-delay=2",
    "dyn-rate (white)": "dyn-rate=0.1@white",
    "mismatch": "mismatch=0.2",
    "all of these": "obs-noise=0.1;ray-dropout=0.05;act-noise=0.1;act-delay=2;dyn-rate=0.1@white;mismatch=0.2",
}
#: the undisturbed single-env measurement, as a script another checkout's Python runs
_OFF_SCRIPT = """
import time, gymnasium as gym, rmm_envs
env = gym.make("Dubins4DGuarded-v0")
a = env.action_space.inactive()
env.reset(seed=0); env.step(a)
n = 0; t0 = time.perf_counter()
for ep in range(EPISODES):
    env.reset(seed=ep); done = False
    while not done:
        *_, te, tr, _ = env.step(a); n += 1; done = te or tr
print((time.perf_counter() - t0) / n)
"""


def single_step_seconds(spec: str | None, episodes: int) -> float:
    """Seconds per step of the single env under ``spec``, driven by its driver, over ``episodes``
    seeded episodes."""
    env = gym.make(ENV, disturbances=spec) if spec else gym.make(ENV)
    a = env.action_space.inactive()
    env.reset(seed=0)
    env.step(a)  # load the compiled paths before timing
    n, t0 = 0, time.perf_counter()
    for ep in range(episodes):
        env.reset(seed=ep)
        done = False
        while not done:
            *_, terminated, truncated, _ = env.step(a)
            n += 1
            done = terminated or truncated
    return (time.perf_counter() - t0) / n


def vector_step_seconds(spec: str | None, steps: int, num_envs: int = 16) -> float:
    """Seconds per sub-env step of the vector env under ``spec`` (autoresets included)."""
    kw = {"disturbances": spec} if spec else {}
    vec = gym.make_vec(ENV, num_envs=num_envs, vectorization_mode="vector_entry_point", **kw)
    vec.reset(seed=0)
    inactive = {
        "active_ctrl": np.zeros(num_envs, np.int64),
        "turnrate_ctrl": np.zeros((num_envs, 1), np.float32),
        "accel_ctrl": np.zeros((num_envs, 1), np.float32),
    }
    vec.step(inactive)
    t0 = time.perf_counter()
    for _ in range(steps):
        vec.step(inactive)
    return (time.perf_counter() - t0) / (steps * num_envs)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5, help="measurements per case; medians are printed (default: 5)")
    p.add_argument("--episodes", type=int, default=10, help="single-env episodes per measurement (default: 10)")
    p.add_argument("--steps", type=int, default=300, help="vector-env steps per measurement (default: 300)")
    p.add_argument("--against", default=None, help="another checkout's Python: the undisturbed step measured there too")
    args = p.parse_args(argv)
    cases = {"off": None, **KINDS}
    single = {k: [] for k in cases}
    vector = {k: [] for k in cases}
    other, here = [], []
    for _ in range(args.repeats):  # the cases interleaved, so a change of load hits them alike
        for name, spec in cases.items():
            single[name].append(single_step_seconds(spec, args.episodes))
            vector[name].append(vector_step_seconds(spec, args.steps))
        if args.against:
            script = _OFF_SCRIPT.replace("EPISODES", str(args.episodes))
            out = subprocess.run([args.against, "-c", script], capture_output=True, text=True, check=True)
            other.append(float(out.stdout.split()[-1]))
            here.append(single_step_seconds(None, args.episodes))
    off_s, off_v = statistics.median(single["off"]), statistics.median(vector["off"])
    print(f"{ENV}, medians of {args.repeats} (driver in control; vector: 16 sub-envs)\n")
    print("| disturbance | single env, us/step | ratio | vector env, us/sub-env step | ratio |")
    print("|---|---:|---:|---:|---:|")
    for name, spec in cases.items():
        s, v = statistics.median(single[name]), statistics.median(vector[name])
        label = "off" if spec is None else f"`{spec}`" if name != "all of these" else "all of these"
        print(f"| {label} | {s * 1e6:.1f} | {s / off_s:.2f} | {v * 1e6:.1f} | {v / off_v:.2f} |")
    if args.against:
        a, b = statistics.median(other), statistics.median(here)
        print(f"\nundisturbed single-env step: {b * 1e6:.1f} us here, {a * 1e6:.1f} us with {args.against}: "
              f"ratio {b / a:.3f}")  # fmt: skip
        print(json.dumps({"here_us": [x * 1e6 for x in here], "other_us": [x * 1e6 for x in other]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
