"""Tutorial: train a guardian with Stable-Baselines3's PPO, then benchmark it next to LRMM and CBF.

    pip install "rmm-envs[rl]"
    python docs/examples/rl_guardian.py                       # the full run (see the tutorial page)
    python docs/examples/rl_guardian.py --timesteps 3000 --episodes 8    # a smoke test

Steps:

1. wrap ``Dubins4DCircles-v0`` so that an RL library can train on it:
   :class:`~rmm_envs.wrappers.FlattenGuardianAction` (a ``Box(-1, 1, (3,))`` action:
   ``[active > 0.5, turn rate, acceleration]`` scaled to the bounds) and
   :class:`~rmm_envs.wrappers.GuardianReward` (goal bonus, collision penalty, a cost per
   simulated second under guardian control);
2. train PPO on several copies of it and save the model (``--model``, a zip file);
3. evaluate it with ``rmm-bench`` on ``Dubins4DParallel-v0`` as the guardian
   ``rl_guardian:PPOGuardian`` (this module's class, given the model file with
   ``--agent-opt rl_guardian:PPOGuardian.model=PATH``), next to ``lrmm``, ``cbf`` and ``inactive``.

Training uses the blocking env (no clock: every step is 0.1 s of simulated time), which is what
the guardian meets in the non-blocking env when it thinks quickly.  ``--timesteps`` sets the
training length, ``--episodes`` the benchmark's episodes per agent, ``--clock`` its clock.

Loading an SB3 model file unpickles parts of it (SB3 stores some objects with cloudpickle):
load only files you trust, as with any pickle.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import gymnasium as gym
import numpy as np

import rmm_envs  # noqa: F401  (registers the environments)
from guardians import Guardian
from rmm_envs.wrappers import FlattenGuardianAction, GuardianReward


def make_training_env(seed: int = 0) -> gym.Env:
    """The env PPO trains on: flat Box actions, shaped reward (defaults of GuardianReward)."""
    env = GuardianReward(FlattenGuardianAction(gym.make("Dubins4DCircles-v0")))
    env.reset(seed=seed)
    return env


class PPOGuardian(Guardian):
    """A PPO policy saved by :func:`train` acting as a guardian (local observation only)."""

    name = "ppo"
    observation_type = "local"

    def __init__(self, model: str = "ppo_guardian.zip", deterministic: bool = True) -> None:
        super().__init__()
        from stable_baselines3 import PPO

        path = Path(model)
        if not path.is_file():
            raise FileNotFoundError(f"PPOGuardian: no model file at {path} (train one with docs/examples/rl_guardian.py)")
        self.policy = PPO.load(str(path), device="cpu")
        self.deterministic = bool(deterministic)

    def act(self, observation, info):
        flat, _ = self.policy.predict(np.asarray(observation, dtype=np.float32), deterministic=self.deterministic)
        return FlattenGuardianAction.to_guardian(self.action_space, flat)


def train(timesteps: int, model_path: Path, n_envs: int = 8, seed: int = 0) -> Path:
    """Train PPO for ``timesteps`` environment steps on ``n_envs`` copies; save to ``model_path``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)  # small networks: one thread is fastest and leaves the other core free
    venv = make_vec_env(make_training_env, n_envs=n_envs, seed=seed)
    model = PPO("MlpPolicy", venv, n_steps=256, batch_size=256, learning_rate=3e-4, gamma=0.995, seed=seed,
                device="cpu", verbose=0)
    model.learn(total_timesteps=timesteps)
    model.save(str(model_path))
    venv.close()
    return model_path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="train a PPO guardian and benchmark it")
    p.add_argument("--timesteps", type=int, default=200_000, help="PPO training steps (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=256, help="benchmark episodes per agent (default: %(default)s)")
    p.add_argument("--clock", default="fixed:1", help="benchmark clock (default: %(default)s)")
    p.add_argument("--model", type=Path, default=None, help="model file (default: a temporary folder)")
    p.add_argument("--out", type=Path, default=None, help="benchmark results folder (default: a temporary folder)")
    p.add_argument("--workers", type=int, default=1, help="benchmark worker processes (default: %(default)s)")
    args = p.parse_args(argv)
    if args.timesteps < 1 or args.episodes < 1:
        p.error(f"--timesteps and --episodes must be >= 1, got {args.timesteps} and {args.episodes}")
    tmp = Path(tempfile.mkdtemp(prefix="rl-guardian-"))
    model_path = args.model or tmp / "ppo_guardian.zip"
    train(args.timesteps, model_path)
    print(f"trained PPO for {args.timesteps} steps -> {model_path}")

    from benchmarks.bench.cli import main as rmm_bench

    out = args.out or tmp / "bench"
    agent = "rl_guardian:PPOGuardian"  # this file's folder is on sys.path when it runs as a script
    rc = rmm_bench(["--agent", f"{agent},lrmm,cbf,inactive", "--agent-opt", f"{agent}.model={model_path}",
                    "--episodes", str(args.episodes), "--workers", str(args.workers), "--clock", args.clock,
                    "--out", str(out), "--no-progress"])
    print((out / "table_I.md").read_text())
    assert rc == 0, f"rmm-bench exited with {rc}"
    # every agent ran every episode (the trained guardian included), without an error
    from benchmarks import load_results

    df = load_results(out)
    counts = df.groupby("agent").size().to_dict()
    assert counts == {a: args.episodes for a in (agent, "lrmm", "cbf", "inactive")}, counts
    assert set(df.outcome) <= {"goal", "collision", "timeout"} and df.error.isna().all()
    ppo = df[df.agent == agent]
    print(f"PPO guardian: {ppo.outcome.eq('collision').mean():.1%} collisions, "
          f"in control {ppo.active_sim_time.sum() / ppo.sim_time.sum():.1%} of the simulated time")
    return rc


if __name__ == "__main__":
    sys.exit(main())
