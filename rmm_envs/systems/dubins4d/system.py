"""The spec of Dubins4D among circles: every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="Dubins4D",
        blurb="a Dubins4D car driven to a goal among five circles by a reckless CLF-QP driver",
        dynamics="rmm_envs.systems.dubins4d.dynamics:Dubins4D",
        scenes=("rmm_envs.systems.dubins4d.scene:Dubins4DScene",),
        envs={
            "guarded": "rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv",
            "parallel": "rmm_envs.systems.dubins4d.env:parallel_env",
        },
        driver="rmm_envs.systems.dubins4d.driver:CLFDriver",
        safe_default="rmm_envs.systems.dubins4d.dynamics:FullBraking",
        guardians=("lrmm", "lrmm-paper", "cbf", "cbf-paper", "hj", "hj-paper", "random", "inactive", "brakes"),
        vector="rmm_envs.systems.dubins4d.vector:Dubins4DCirclesVectorEnv",
        pages=(
            DocPage(
                "environments/dubins4d.md",
                "Dubins4D among circles",
                ("guarded", "parallel"),
                "figures/dubins4d_frame.png",
            ),
        ),
        stored={"guarded": "Dubins4DCircles-v0"},
        former={"Dubins4DCirclesGuarded-v0": "guarded", "Dubins4DCirclesParallel-v0": "parallel"},
        view="rmm_envs.systems.dubins4d.view:dubins4d_view",
        doomed_test="rmm_envs.systems.dubins4d.doomed:dubins4d_test",
    )
