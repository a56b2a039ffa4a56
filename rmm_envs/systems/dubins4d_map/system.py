"""The spec of Dubins4D on a map of your own: every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="Dubins4DMap",
        blurb="the same car and driver on a JSON map of your own (circles, polygons, walls; pymunk)",
        dynamics="rmm_envs.systems.dubins4d.dynamics:Dubins4D",
        scenes=("rmm_envs.systems.dubins4d_map.scene:Dubins4DMapScene",),
        envs={
            "guarded": "rmm_envs.systems.dubins4d_map.env:Dubins4DMapEnv",
            "parallel": "rmm_envs.systems.dubins4d_map.env:parallel_env",
        },
        driver="rmm_envs.systems.dubins4d.driver:CLFDriver",
        safe_default="rmm_envs.systems.dubins4d.dynamics:FullBraking",
        guardians=("lrmm", "lrmm-paper", "random", "inactive", "brakes"),
        extra="map",
        pages=(
            DocPage(
                "environments/dubins4d_map.md",
                "Dubins4D on a map of your own",
                ("guarded", "parallel"),
                "figures/dubins4d_map_frame.png",
            ),
        ),
        stored={"guarded": "Dubins4DMap-v0"},
        view="rmm_envs.systems.dubins4d_map.view:map_view",
        doomed_test="rmm_envs.systems.dubins4d_map.doomed:dubins4d_map_test",
    )
