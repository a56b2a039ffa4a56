"""The spec of the maze car (Dubins3D in mazes): every part of the system, named once
(:class:`rmm_envs.catalog.SystemSpec`)."""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["spec"]


def spec() -> SystemSpec:
    """This system, as the table of systems holds it (registered by :func:`rmm_envs.builtin.systems`)."""
    return SystemSpec(
        name="Dubins3DMaze",
        blurb="a constant-speed Dubins car in procedurally generated mazes, guarded from a corner-cutting pursuit driver",
        dynamics="rmm_envs.systems.maze.dynamics:Dubins3D",
        scenes=("rmm_envs.systems.maze.scene:MazeScene",),
        envs={
            "plain": "rmm_envs.systems.maze.env:Dubins3DMazeEnv",
            "guarded": "rmm_envs.systems.maze.guarded:Dubins3DMazeGuardedEnv",
            "parallel": "rmm_envs.systems.maze.guarded:parallel_env",
        },
        driver="rmm_envs.systems.maze.driver:PursuitDriver",
        safe_default="rmm_envs.systems.maze.observation:TurnFromNearerWall",
        guardians=("lrmm", "cbf", "hj", "random", "inactive", "brakes"),
        pages=(
            DocPage(
                "environments/dubins3d_maze.md", "Dubins3D in mazes", ("plain",), "figures/dubins3d_maze_frame.png"
            ),
            DocPage(
                "environments/dubins3d_maze_parallel.md",
                "The maze car under parallel autonomy",
                ("guarded", "parallel"),
            ),
        ),
        view="rmm_envs.systems.maze.view:maze_view",
        doomed_test="rmm_envs.systems.maze.doomed:maze_test",
    )
