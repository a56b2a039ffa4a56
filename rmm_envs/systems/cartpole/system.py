"""The spec of CartPole under the target task: every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="CartPole",
        blurb="Gymnasium's CartPole-v1 driven to a target position by a reckless LQR, the balancing LQR as safe default",
        dynamics="gymnasium.envs.classic_control.cartpole:CartPoleEnv",
        scenes=("rmm_envs.adapters.classic_control:CartPoleScene",),
        envs={
            "guarded": "rmm_envs.systems.cartpole.guarded:guarded_env",
            "parallel": "rmm_envs.systems.cartpole.guarded:parallel_env",
        },
        driver="rmm_envs.envs.target_driver:TargetDriver",
        safe_default="rmm_envs.envs.any_env:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        pages=(
            DocPage(
                "environments/driven_examples.md",
                "Simulators the project did not write, guarded",
                ("guarded", "parallel"),
            ),
        ),
        view="rmm_envs.systems.cartpole.view:cartpole_view",
    )
