"""The spec of InvertedPendulum under the target task: every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="InvertedPendulum",
        blurb="Gymnasium's MuJoCo InvertedPendulum-v5 under the same target task (see the CartPole page)",
        dynamics="gymnasium.envs.mujoco.inverted_pendulum_v5:InvertedPendulumEnv",
        scenes=("rmm_envs.adapters.mujoco_envs:MujocoScene",),
        envs={
            "guarded": "rmm_envs.systems.pendulum.guarded:guarded_env",
            "parallel": "rmm_envs.systems.pendulum.guarded:parallel_env",
        },
        driver="rmm_envs.envs.target_driver:TargetDriver",
        safe_default="rmm_envs.envs.any_env:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        extra="mujoco",
        view="rmm_envs.systems.pendulum.view:pendulum_view",
    )
