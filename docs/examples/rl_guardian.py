"""Tutorial: train a guardian with Stable-Baselines3's PPO, then benchmark it next to LRMM and CBF.

    pip install -e ".[rl]"                                    # in a clone of the repository
    python docs/examples/rl_guardian.py                       # the full run (see the tutorial page)
    python docs/examples/rl_guardian.py --timesteps 3000 --episodes 8    # a smoke test
    python docs/examples/rl_guardian.py --cost-limit 0.1      # constrained: PPO-Lagrangian on info["cost"]

Steps:

1. wrap ``Dubins4DGuarded-v0`` so that an RL library can train on it:
   :class:`~rmm_envs.wrappers.FlattenGuardianAction` (a ``Box(-1, 1, (3,))`` action:
   ``[active > 0.5, turn rate, acceleration]`` scaled to the bounds) and
   :class:`~rmm_envs.wrappers.GuardianReward` (goal bonus, collision penalty, a cost per
   simulated second under guardian control);
2. train PPO on several copies of it and save the model (``--model``, a zip file); with
   ``--cost-limit C``, constrained (PPO-Lagrangian): the reward has no collision penalty, each
   step's ``info["cost"]`` (1 on a collision) is charged at a multiplier ``lam`` that rises
   while the episodes' mean cost exceeds ``C`` and falls (to 0 at least) while below
   (:class:`LagrangianPenalty`, :class:`LagrangeUpdate`);
3. evaluate it with ``rmm-bench`` on ``Dubins4DParallel-v0`` as the guardian
   ``rl_guardian:PPOGuardian`` (this module's class, an :class:`rmm_guardians.SB3Guardian` reading
   the model's flat actions exactly as the training wrapper did; given the model file with
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
from rmm_envs.wrappers import FlattenGuardianAction, GuardianReward
from rmm_guardians import SB3Guardian


def make_training_env(seed: int = 0) -> gym.Env:
    """The env PPO trains on: flat Box actions, shaped reward (defaults of GuardianReward)."""
    env = GuardianReward(FlattenGuardianAction(gym.make("Dubins4DGuarded-v0")))
    env.reset(seed=seed)
    return env


class LagrangianPenalty(gym.Wrapper):
    """``reward - lam * info["cost"]``, ``lam`` read from a shared one-element array (the
    multiplier :class:`LagrangeUpdate` adapts)."""

    def __init__(self, env: gym.Env, lam: np.ndarray) -> None:
        super().__init__(env)
        self.lam = lam

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        return obs, reward - float(self.lam[0]) * info["cost"], terminated, truncated, info


def make_constrained_env(lam: np.ndarray, seed: int = 0) -> gym.Env:
    """The constrained problem: goal bonus and intervention cost as the reward, no collision
    penalty; collisions enter through ``info["cost"]`` at the multiplier ``lam``."""
    env = LagrangianPenalty(
        GuardianReward(FlattenGuardianAction(gym.make("Dubins4DGuarded-v0")), collision_penalty=0.0), lam
    )
    env.reset(seed=seed)
    return env


def lagrange_step(lam: float, mean_cost: float, cost_limit: float, lr: float) -> float:
    """Dual ascent on the multiplier: ``max(0, lam + lr (mean episode cost - cost_limit))``."""
    return max(0.0, lam + lr * (mean_cost - cost_limit))


def make_lagrange_update(lam: np.ndarray, cost_limit: float, lr: float):
    """A Stable-Baselines3 callback: sums each env's ``info["cost"]`` over its episodes and,
    after every rollout, moves ``lam`` by :func:`lagrange_step` on the mean episode cost."""
    from stable_baselines3.common.callbacks import BaseCallback

    class LagrangeUpdate(BaseCallback):
        def _on_training_start(self) -> None:
            self.running = np.zeros(self.training_env.num_envs)
            self.finished: list[float] = []
            self.history: list[tuple[float, float]] = []  # (mean episode cost, lam after the update)

        def _on_step(self) -> bool:
            self.running += [info["cost"] for info in self.locals["infos"]]
            for i in np.flatnonzero(self.locals["dones"]):
                self.finished.append(float(self.running[i]))
                self.running[i] = 0.0
            return True

        def _on_rollout_end(self) -> None:
            if self.finished:
                mean = float(np.mean(self.finished))
                lam[0] = lagrange_step(float(lam[0]), mean, cost_limit, lr)
                self.history.append((mean, float(lam[0])))
                self.finished = []

    return LagrangeUpdate()


class PPOGuardian(SB3Guardian):
    """A PPO policy saved by :func:`train` acting as a guardian (local observation only): the
    model's flat actions are read by :class:`rmm_guardians.SB3Guardian` through the same mapping
    :class:`FlattenGuardianAction` trained it with."""

    observation_type = "local"

    def __init__(self, model: str = "ppo_guardian.zip", deterministic: bool = True) -> None:
        from stable_baselines3 import PPO

        path = Path(model)
        if not path.is_file():
            raise FileNotFoundError(
                f"PPOGuardian: no model file at {path} (train one with docs/examples/rl_guardian.py)"
            )
        super().__init__(PPO.load(str(path), device="cpu"), name="ppo", deterministic=bool(deterministic))


def train(
    timesteps: int,
    model_path: Path,
    n_envs: int = 8,
    seed: int = 0,
    cost_limit: float | None = None,
    lam_lr: float = 0.5,
) -> Path:
    """Train PPO for ``timesteps`` environment steps on ``n_envs`` copies; save to ``model_path``.
    With ``cost_limit``, PPO-Lagrangian (module docstring), the multiplier's step ``lam_lr``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    torch.set_num_threads(1)  # small networks: one thread is fastest and leaves the other core free
    callback = None
    if cost_limit is None:
        venv = make_vec_env(make_training_env, n_envs=n_envs, seed=seed)
    else:
        lam = np.zeros(1)  # shared by the envs of the (in-process) vector env and the callback
        venv = make_vec_env(make_constrained_env, n_envs=n_envs, seed=seed, env_kwargs={"lam": lam})
        callback = make_lagrange_update(lam, cost_limit, lam_lr)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=256,
        batch_size=256,
        learning_rate=3e-4,
        gamma=0.995,
        seed=seed,
        device="cpu",
        verbose=0,
    )
    model.learn(total_timesteps=timesteps, callback=callback)
    model.save(str(model_path))
    venv.close()
    if callback is not None:
        for k, (mean, lam_now) in enumerate(callback.history):
            print(f"rollout {k}: mean episode cost {mean:.3f} (limit {cost_limit}), lambda -> {lam_now:.3f}")
    return model_path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description="train a PPO guardian and benchmark it")
    p.add_argument("--timesteps", type=int, default=200_000, help="PPO training steps (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=256, help="benchmark episodes per agent (default: %(default)s)")
    p.add_argument("--clock", default="fixed:1", help="benchmark clock (default: %(default)s)")
    p.add_argument("--model", type=Path, default=None, help="model file (default: a temporary folder)")
    p.add_argument("--out", type=Path, default=None, help="benchmark results folder (default: a temporary folder)")
    p.add_argument("--workers", type=int, default=1, help="benchmark worker processes (default: %(default)s)")
    p.add_argument(
        "--cost-limit",
        type=float,
        default=None,
        help="train PPO-Lagrangian with this limit on the mean episode cost (default: plain PPO)",
    )
    args = p.parse_args(argv)
    if args.timesteps < 1 or args.episodes < 1:
        p.error(f"--timesteps and --episodes must be >= 1, got {args.timesteps} and {args.episodes}")
    if args.cost_limit is not None and not 0.0 <= args.cost_limit <= 1.0:
        p.error(f"--cost-limit must be in [0, 1] (a mean number of collisions per episode), got {args.cost_limit}")
    tmp = Path(tempfile.mkdtemp(prefix="rl-guardian-"))
    model_path = args.model or tmp / "ppo_guardian.zip"
    train(args.timesteps, model_path, cost_limit=args.cost_limit)
    print(f"trained PPO for {args.timesteps} steps -> {model_path}")

    from rmm_bench.cli import main as rmm_bench

    out = args.out or tmp / "bench"
    agent = "rl_guardian:PPOGuardian"  # this file's folder is on sys.path when it runs as a script
    rc = rmm_bench(
        [
            "--agent",
            f"{agent},lrmm,cbf,inactive",
            "--agent-opt",
            f"{agent}.model={model_path}",
            "--episodes",
            str(args.episodes),
            "--workers",
            str(args.workers),
            "--clock",
            args.clock,
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    print((out / "table_I.md").read_text())
    assert rc == 0, f"rmm-bench exited with {rc}"
    # every agent ran every episode (the trained guardian included), without an error
    from rmm_bench import load_results

    df = load_results(out)
    counts = df.groupby("agent").size().to_dict()
    assert counts == {a: args.episodes for a in (agent, "lrmm", "cbf", "inactive")}, counts
    assert set(df.outcome) <= {"goal", "collision", "timeout"} and df.error.isna().all()
    ppo = df[df.agent == agent]
    print(
        f"PPO guardian: {ppo.outcome.eq('collision').mean():.1%} collisions, "
        f"in control {ppo.active_sim_time.sum() / ppo.sim_time.sum():.1%} of the simulated time"
    )
    return rc


if __name__ == "__main__":
    sys.exit(main())
