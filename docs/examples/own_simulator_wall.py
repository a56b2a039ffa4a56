"""Your own simulator, end to end: a cart before a wall, from the snapshot protocol to Table I.

    python docs/examples/own_simulator_wall.py                                   # the documented size
    python docs/examples/own_simulator_wall.py --configs 4 --samples 32 --epochs 100 --episodes 16

This file is two things.  Imported (``--env own_simulator_wall:CartWall-v0``), it is the module
a user writes: ``CartWall``, a simulator in plain numpy that knows nothing of rmm_envs (the
snapshot protocol and a few optional hooks: rmm_envs.envs.any_env.SIMULATOR_HOOKS), a reckless
driver, a braking safe default, and the env ``CartWall-v0`` registered with ``guarded``.  Run,
it takes that env the whole way, running each command in this process with exactly the
arguments it prints: (1) risk labels of two states, by hand and by the estimator; (2)
``rmm-datagen``; (3) ``rmm-train``, a model of the env's own observation; (4) ``rmm-bench``
with ``lrmm`` (the safe default while the predicted risk is above the threshold), ``inactive``
(the driver alone) and ``random``: Table I, where lrmm must fail less often than inactive.
"""

from __future__ import annotations

import argparse
import csv
import json
import shlex
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

WALL = 2.0  # m: the cart fails when it reaches the wall


class CartWall:
    """A cart on a rail, pushed by an acceleration in [-1, 1] m/s^2 held for each 0.1 s step;
    a wall at x = 2 m.  State (x, v); the observation is (distance to the wall, v)."""

    dt = 0.1
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
    default_horizon = 0.5  # s: each random control of a risk label is held for 5 steps

    def __init__(self):
        self.x, self.v = 0.0, 0.0

    # -- the snapshot protocol ----------------------------------------------------------------
    def get_state(self):
        return np.array([self.x, self.v])

    def set_state(self, state):
        self.x, self.v = float(state[0]), float(state[1])

    def step(self, action):  # True when this step reaches the wall
        a = float(action[0])
        self.x += self.dt * (self.v + 0.5 * self.dt * a)
        self.v += self.dt * a
        return self.x >= WALL

    def state_failed(self, states):
        return np.asarray(states)[:, 0] >= WALL

    # -- optional hooks --------------------------------------------------------------------------
    def step_batch(self, states, actions):  # step on many states at once: labels at array speed
        x, v, a = states[:, 0], states[:, 1], actions[:, 0].astype(float)
        out = np.empty_like(states)  # each column written in place: no temporaries to stack
        np.add(x, self.dt * (v + 0.5 * self.dt * a), out=out[:, 0])  # step's arithmetic: the same bits
        np.add(v, self.dt * a, out=out[:, 1])
        return out, out[:, 0] >= WALL

    def observe(self, state):
        return np.array([WALL - state[0], state[1]], dtype=np.float32)

    def sample_states(self, rng, n):  # for rmm-datagen: anywhere on the rail, at any speed the driver reaches
        return np.column_stack([rng.uniform(-0.5, WALL, n), rng.uniform(-2.5, 2.5, n)])

    def render(self, state):  # a 32 x 128 picture: the rail from -0.5 m to the wall, the cart in white
        frame = np.zeros((32, 128, 3), dtype=np.uint8)
        frame[:, -4:] = (200, 60, 60)  # the wall
        col = int(np.clip((state[0] + 0.5) / (WALL + 0.5) * 123, 0, 123))
        frame[12:20, col : col + 4] = 255
        return frame


class Driver:
    """Drives to a random mark before the wall with a random, often too high, gain: it
    overshoots into the wall in about half the episodes."""

    def begin_episode(self, rng):  # called by the guarded env at every reset
        self.mark, self.gain, self.held = rng.uniform(1.0, 1.9), rng.uniform(1.0, 4.0), 0

    def __call__(self, obs):
        x, v = WALL - float(obs[0]), float(obs[1])
        return np.array([np.clip(self.gain * (self.mark - x) - 0.8 * v, -1.0, 1.0)], dtype=np.float32)

    def arrived(self, obs):  # success: within 5 cm of the mark, nearly still, for 0.5 s
        x = WALL - float(obs[0])
        self.held = self.held + 1 if abs(x - self.mark) < 0.05 and abs(float(obs[1])) < 0.05 else 0
        return self.held >= 5


def brake(obs):
    """The safe default: brake to a stop."""
    return np.array([np.clip(-2.0 * float(obs[1]), -1.0, 1.0)], dtype=np.float32)


def make_cart_wall(clock=None, render_mode=None):
    """``CartWall-v0``: the blocking guarded env (rmm-bench passes the clock)."""
    from rmm_envs.envs.any_env import guarded

    driver = Driver()
    return guarded(
        CartWall(),
        driver=driver,
        safe_default=brake,
        success=driver.arrived,
        controls=("accel",),
        max_episode_sim_time=10.0,
        clock=clock,
        render_mode=render_mode,
    )


if "CartWall-v0" not in gym.registry:
    gym.register("CartWall-v0", entry_point=make_cart_wall)

ENV = "own_simulator_wall:CartWall-v0"


def run(name, main, argv):
    """Run a command's ``main(argv)`` here, printing it as the shell command it is."""
    print("$", name, " ".join(shlex.quote(a) for a in argv), flush=True)
    status = main(argv)
    assert status in (0, None), f"{name} exited with {status}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=None, help="working directory (default: a temporary one)")
    ap.add_argument("--configs", type=int, default=8, help="rmm-datagen --configs (default: %(default)s)")
    ap.add_argument("--samples", type=int, default=64, help="rmm-datagen --samples-per-config (default: %(default)s)")
    ap.add_argument("--epochs", type=int, default=200, help="rmm-train --epochs (default: %(default)s)")
    ap.add_argument("--episodes", type=int, default=64, help="rmm-bench --episodes (default: %(default)s)")
    args = ap.parse_args(argv)
    work = Path(args.out or tempfile.mkdtemp(prefix="own-simulator-wall-"))
    here = str(Path(__file__).resolve().parent)
    if here not in sys.path:  # --env own_simulator_wall:CartWall-v0 imports this file as a module
        sys.path.insert(0, here)

    from rmm_bench.cli import main as rmm_bench
    from rmm_envs.adapters import SnapshotScene
    from rmm_envs.risk import RiskEstimator
    from rmm_envs.risk.datagen import main as rmm_datagen
    from rmm_guardians.lrmm.train import main as rmm_train

    # 1. labels: at rest 0.5 m from the wall nothing reaches it in two 0.5 s levels (at most
    #    0.5 m at full push); at 2 m/s 0.1 m from it, every control does within the first step
    scene = SnapshotScene(CartWall(), default_horizon=CartWall.default_horizon)
    risk = RiskEstimator(scene, horizon=0.5).estimate(np.array([[1.5, 0.0], [1.9, 2.0]]), np.random.default_rng(0))
    print(f"risk at rest 0.5 m from the wall: {risk.risk[0]:.2f}; at 2 m/s 0.1 m from it: {risk.risk[1]:.2f}")
    assert risk.risk.tolist() == [0.0, 1.0]

    # 2. a dataset: half of each configuration's states from CartWall.sample_states, half
    #    from the states the driver alone visits
    data, model, bench = work / "data", work / "cart_wall.npz", work / "bench"
    run(
        "rmm-datagen",
        rmm_datagen,
        ["--env", ENV, "--configs", str(args.configs), "--samples-per-config", str(args.samples)]
        + ["--seed", "0", "--workers", "1", "--no-progress", "--out", str(data)],
    )
    # 3. a risk map of the env's own observation (distance to the wall, speed)
    run(
        "rmm-train",
        rmm_train,
        ["--data", str(data), "--out", str(model), "--hidden", "32", "32", "--activation", "tanh"]
        + ["--output-bias", "--lr", "0.003", "--epochs", str(args.epochs), "--quiet"],
    )
    # 4. Table I: lrmm brakes (the safe default) while the predicted risk is above 0.3
    run(
        "rmm-bench",
        rmm_bench,
        ["--env", ENV, "--agent", "lrmm,inactive,random", "--agent-opt", f"lrmm.model={json.dumps(str(model))}"]
        + ["--agent-opt", "lrmm.threshold=0.3", "--clock", "fixed:1"]
        + ["--episodes", str(args.episodes), "--seed", "0", "--workers", "1", "--no-progress", "--out", str(bench)],
    )
    with open(bench / "table_I.csv") as f:
        rows = {r["agent"]: r for r in csv.DictReader(f)}
    collisions = {a: float(r["collision_mean"]) for a, r in rows.items()}
    print("collision rate [% eps]:", ", ".join(f"{a} {c:.1f}" for a, c in collisions.items()))
    assert collisions["lrmm"] < collisions["inactive"], collisions
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
