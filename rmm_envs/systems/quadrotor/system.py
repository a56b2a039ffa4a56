"""The spec of the quadrotor in rooms: every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="QuadrotorRoom",
        blurb="a quadrotor in procedurally generated rooms (PyBullet), flown through waypoints by a reckless pilot",
        dynamics="rmm_envs.systems.quadrotor.body:Quadrotor",
        scenes=(
            "rmm_envs.systems.quadrotor.scene:QuadrotorScene",
            "rmm_envs.systems.quadrotor.scene:QuadrotorCommandScene",
        ),
        envs={
            "plain": "rmm_envs.systems.quadrotor.env:QuadrotorRoomEnv",
            "guarded": "rmm_envs.systems.quadrotor.guarded:QuadrotorRoomGuardedEnv",
            "parallel": "rmm_envs.systems.quadrotor.guarded:parallel_env",
        },
        driver="rmm_envs.systems.quadrotor.driver:WaypointPilot",
        safe_default="rmm_envs.systems.quadrotor.control:HoverAndLevel",
        guardians=("lrmm", "cbf", "hj", "random", "inactive", "brakes"),
        extra="quadrotor",
        pages=(
            DocPage(
                "environments/quadrotor_room.md", "Quadrotor in rooms", ("plain",), "figures/quadrotor_room_frame.png"
            ),
            DocPage(
                "environments/quadrotor_room_parallel.md",
                "The quadrotor under parallel autonomy",
                ("guarded", "parallel"),
            ),
        ),
        view="rmm_envs.systems.quadrotor.view:quadrotor_view",
        doomed_test="rmm_envs.systems.quadrotor.doomed:quadrotor_test",
    )
