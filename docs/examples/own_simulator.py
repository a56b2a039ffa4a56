"""Tutorial: risk maps for a simulator the project did not write.

    python docs/examples/own_simulator.py                       # small and quick
    python docs/examples/own_simulator.py --configs 64 --samples 128 --epochs 200

Steps: (1) RiskLabel labels Gymnasium's CartPole-v1 while it runs, through the risk adapter
chosen for it; Pendulum-v1 needs a failure test of the state; (2) a simulator of your own is
labelled through the snapshot protocol; (3) rmm-datagen's API labels CartPole states from the
adapter's sampler; (4) rmm-train's API fits a risk map to them, read from the env's own
observation; (5) a driver, a safe default and a success test make CartPole-v1 a guarded env,
which is labelled, learned and benchmarked (rmm-bench's Table I) like the package's own.
"""

import argparse
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

from rmm_bench.cli import main as rmm_bench
from rmm_envs.adapters import SnapshotScene
from rmm_envs.envs.any_env import parallel
from rmm_envs.risk import RiskEstimator
from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset
from rmm_envs.wrappers import RiskLabel
from rmm_guardians.lrmm.train import TrainConfig, train


class Cliff:
    """A simulator of one's own: a cart on a rail at the held speed; a step ending past x = 1
    falls off the cliff (the step reports the failure)."""

    dt = 0.1
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.x = np.zeros(1)

    def get_state(self):
        return self.x.copy()

    def set_state(self, state):
        self.x = np.array(state, dtype=float)

    def step(self, action):
        self.x = self.x + self.dt * float(action[0])
        return bool(self.x[0] > 1.0)

    def state_failed(self, states):
        return np.zeros(len(states), dtype=bool)


#: a balancing LQR of CartPole's linearised equations, u = -K (x, x_dot, theta, theta_dot)
K = (-3.16, -5.92, -49.5, -12.8)


def push(obs, mark=0.0, gain=1.0):
    """CartPole's action (1: push right) of the LQR steering to ``mark``, its position gain times ``gain``."""
    u = -K[0] * gain * (float(obs[0]) - mark) - sum(k * float(x) for k, x in zip(K[1:], obs[1:], strict=True))
    return int(u > 0)


class RushToTheMark:
    """A reckless driver: to a random mark right of the centre, with an aggressive position gain."""

    def begin_episode(self, rng):  # called by the guarded env at every reset
        self.mark, self.gain, self.held = rng.uniform(1.0, 1.8), rng.uniform(1.0, 4.0), 0

    def __call__(self, obs):
        return push(obs, self.mark, self.gain)

    def arrived(self, obs):  # success: at the mark with the pole up for 0.5 s (25 steps)
        self.held = self.held + 1 if abs(obs[0] - self.mark) < 0.2 and abs(obs[2]) < 0.05 else 0
        return self.held >= 25


def make_rush_cartpole(time_accel=10.0, base_step=0.02, clock=None):
    """The non-blocking guarded env (rmm-bench passes the clock, time_accel and base_step)."""
    driver = RushToTheMark()
    return parallel(
        "CartPole-v1",
        driver=driver,
        safe_default=push,
        success=driver.arrived,
        controls=("force_ctrl",),
        max_episode_sim_time=6.0,
        time_accel=time_accel,
        base_step=base_step,
        clock=clock,
    )


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default=None, help="working directory (default: a temporary one)")
    ap.add_argument("--configs", type=int, default=8)
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--episodes", type=int, default=16, help="Table I episodes per guardian")
    args = ap.parse_args(argv)
    work = Path(args.out or tempfile.mkdtemp(prefix="own-simulator-"))

    # 1. labels while the env runs: the adapter is chosen by RiskLabel (n = 32, m = 2, and the
    #    adapter's own horizon, 0.08 s = 4 CartPole steps)
    env = RiskLabel(gym.make("CartPole-v1"), seed=0)
    obs, info = env.reset(seed=0)
    risks = [info["risk"]]
    for _ in range(20):  # always push right: the pole tips over, the label rises
        obs, reward, terminated, truncated, info = env.step(1)
        risks.append(info["risk"])
        if terminated:
            break
    print("CartPole, always pushing right:", " ".join(f"{r:.2f}" for r in risks))
    assert all(0.0 <= r <= 1.0 for r in risks) and risks[-1] == 1.0 and risks[0] < 1.0

    pendulum = RiskLabel(gym.make("Pendulum-v1"), failure=lambda s: np.abs(s[:, 1]) > 6.0, seed=0)
    obs, info = pendulum.reset(seed=0)
    print(f"Pendulum (fails beyond 6 rad/s): risk {info['risk']:.2f} at theta = {pendulum.unwrapped.state[0]:.2f} rad")

    # 2. a simulator of your own: the snapshot protocol (get_state, set_state, step, state_failed,
    #    dt, action_space); one level of 0.5 s: from x = 0.8 a speed above 0.4 falls off
    scene = SnapshotScene(Cliff(), name="Cliff", default_horizon=0.5)
    est = RiskEstimator(scene, branches=1000, depth=1, horizon=0.5)
    r = est.estimate(np.array([[0.0], [0.8]]), np.random.default_rng(0)).risk
    print(f"Cliff: risk {r[0]:.2f} at x = 0, {r[1]:.2f} at x = 0.8 (exact: 0, 0.3)")
    assert r[0] == 0.0 and abs(r[1] - 0.3) < 0.05

    # 3. a dataset (rmm-datagen --env CartPole-v1): each "configuration" is a seeded reset, its
    #    states come from the adapter's sampler (uniform on the non-failed box)
    cfg = DatagenConfig(env_id="CartPole-v1", configs=args.configs, samples_per_config=args.samples, seed=0)
    manifest = generate(cfg, work / "data", workers=1, progress=False)
    data = load_dataset(work / "data")
    print(
        f"labelled {len(data)} CartPole states; mean risk {data.risk.mean():.3f}, horizon "
        f"{data.meta['estimator']['horizon']} s; dataset {manifest['dataset_sha256'][:12]}"
    )
    assert data.obs.shape == (args.configs * args.samples, 4) and data.meta["estimator"]["horizon"] == 0.08

    # 4. a risk map from the env's own observation (rmm-train --data ... --out ...)
    model = train(data, TrainConfig(epochs=args.epochs, seed=0), log=lambda *a: None)
    model.save(work / "cartpole_model.npz")
    upright, tipping = np.array([[0, 0, 0, 0]], np.float32), np.array([[0, 0, 0.19, 1.5]], np.float32)
    print(
        f"model: test MAE {model.meta['metrics']['test']['mae']:.3f}; predicted risk upright at rest "
        f"{float(model.predict(upright)[0]):.2f}, tipping over {float(model.predict(tipping)[0]):.2f}"
    )

    # 5. parallel autonomy: CartPole-v1 with a reckless driver, the balancing LQR at the centre as
    #    the safe default and "at the mark" as success (rmm_envs.envs.any_env.parallel); its
    #    failure is CartPole's termination.  Registered here; in a module of your own, rmm-bench
    #    --env mymodule:RushCartPole-v0 imports it in every worker.
    if "RushCartPole-v0" not in gym.registry:
        gym.register("RushCartPole-v0", entry_point=make_rush_cartpole)
    gcfg = DatagenConfig(env_id="RushCartPole-v0", configs=args.configs, samples_per_config=args.samples, seed=1)
    generate(gcfg, work / "rush_data", workers=1, progress=False)  # labels at the adapter's horizon, 0.08 s
    rush = train(
        load_dataset(work / "rush_data"),
        TrainConfig(epochs=args.epochs, seed=0, hidden=(64, 64), activation="tanh", output_bias=True, lr=0.003),
        log=lambda *a: None,
    )
    rush.save(work / "rush_model.npz")
    # Table I: the driver alone (inactive), lrmm applying the safe default while the risk is
    # above 0.2, and the safe default throughout (brakes); fixed 1 ms clock, one worker
    status = rmm_bench(
        [
            "--env",
            "RushCartPole-v0",
            "--agent",
            "inactive,lrmm,brakes",
            "--episodes",
            str(args.episodes),
            "--agent-opt",
            f'lrmm.model="{work / "rush_model.npz"}"',
            "--agent-opt",
            "lrmm.threshold=0.2",
            "--seed",
            "0",
            "--clock",
            "fixed:1",
            "--workers",
            "1",
            "--no-progress",
            "--out",
            str(work / "bench"),
        ]
    )
    assert status == 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
