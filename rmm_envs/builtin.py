"""The systems this package ships, each declared as one :class:`~rmm_envs.catalog.SystemSpec`.

Each function returns one system's spec; :func:`systems` returns them all, in the order of the
table (and of ``rmm_envs.ENV_IDS``), and is this package's entry point in the group
``rmm_envs.systems`` (pyproject.toml), the way a package of your own registers its systems
(:mod:`rmm_envs.catalog`); nothing else reads this module.
"""

from __future__ import annotations

from rmm_envs.catalog import DocPage, SystemSpec

__all__ = ["cartpole", "dubins3d_maze", "dubins4d", "dubins4d_map", "inverted_pendulum", "quadrotor_room", "systems"]

_DUBINS4D_GUARDIANS = ("lrmm", "lrmm-paper", "cbf", "cbf-paper", "hj", "hj-paper", "random", "inactive", "brakes")


def dubins4d() -> SystemSpec:
    return SystemSpec(
        name="Dubins4D",
        blurb="a Dubins4D car driven to a goal among five circles by a reckless CLF-QP driver",
        dynamics="rmm_envs.dynamics.dubins4d:Dubins4D",
        scenes=("rmm_envs.scenes.dubins4d:Dubins4DScene",),
        envs={
            "guarded": "rmm_envs.envs.dubins4d:Dubins4DCirclesEnv",
            "parallel": "rmm_envs.envs.dubins4d:make_parallel_env",
        },
        driver="rmm_envs.drivers.dubins4d:CLFDriver",
        safe_default="rmm_envs.dynamics.dubins4d:FullBraking",
        guardians=_DUBINS4D_GUARDIANS,
        vector="rmm_envs.envs.dubins4d_vector:Dubins4DCirclesVectorEnv",
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
        view="rmm_envs.views.planar:dubins4d_view",
        doomed_test="rmm_envs.doomed:dubins4d_test",
    )


def dubins4d_map() -> SystemSpec:
    return SystemSpec(
        name="Dubins4DMap",
        blurb="the same car and driver on a JSON map of your own (circles, polygons, walls; pymunk)",
        dynamics="rmm_envs.dynamics.dubins4d:Dubins4D",
        scenes=("rmm_envs.scenes.dubins4d_map:Dubins4DMapScene",),
        envs={
            "guarded": "rmm_envs.envs.dubins4d_map:Dubins4DMapEnv",
            "parallel": "rmm_envs.envs.dubins4d_map:make_parallel_env",
        },
        driver="rmm_envs.drivers.dubins4d:CLFDriver",
        safe_default="rmm_envs.dynamics.dubins4d:FullBraking",
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
        view="rmm_envs.views.planar:map_view",
        doomed_test="rmm_envs.doomed:dubins4d_map_test",
    )


def dubins3d_maze() -> SystemSpec:
    return SystemSpec(
        name="Dubins3DMaze",
        blurb="a constant-speed Dubins car in procedurally generated mazes, guarded from a corner-cutting pursuit driver",
        dynamics="rmm_envs.dynamics.dubins3d:Dubins3D",
        scenes=("rmm_envs.scenes.maze:MazeScene",),
        envs={
            "plain": "rmm_envs.envs.dubins3d_maze:Dubins3DMazeEnv",
            "guarded": "rmm_envs.envs.dubins3d_maze_parallel:Dubins3DMazeGuardedEnv",
            "parallel": "rmm_envs.envs.dubins3d_maze_parallel:make_parallel_env",
        },
        driver="rmm_envs.drivers.maze:PursuitDriver",
        safe_default="rmm_envs.envs.dubins3d_maze_parallel:TurnFromNearerWall",
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
        view="rmm_envs.views.planar:maze_view",
        doomed_test="rmm_envs.doomed:maze_test",
    )


def quadrotor_room() -> SystemSpec:
    return SystemSpec(
        name="QuadrotorRoom",
        blurb="a quadrotor in procedurally generated rooms (PyBullet), flown through waypoints by a reckless pilot",
        dynamics="rmm_envs.dynamics.quadrotor:Quadrotor",
        scenes=("rmm_envs.scenes.quadrotor:QuadrotorScene", "rmm_envs.scenes.quadrotor:QuadrotorCommandScene"),
        envs={
            "plain": "rmm_envs.envs.quadrotor_room:QuadrotorRoomEnv",
            "guarded": "rmm_envs.envs.quadrotor_room_parallel:QuadrotorRoomGuardedEnv",
            "parallel": "rmm_envs.envs.quadrotor_room_parallel:make_parallel_env",
        },
        driver="rmm_envs.drivers.quadrotor:WaypointPilot",
        safe_default="rmm_envs.dynamics.quadrotor_control:HoverAndLevel",
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
        view="rmm_envs.views.quadrotor:quadrotor_view",
        doomed_test="rmm_envs.doomed:quadrotor_test",
    )


# simulators the project did not write, made guarded envs by rmm_envs.envs.driven.guarded
def cartpole() -> SystemSpec:
    return SystemSpec(
        name="CartPole",
        blurb="Gymnasium's CartPole-v1 driven to a target position by a reckless LQR, the balancing LQR as safe default",
        dynamics="gymnasium.envs.classic_control.cartpole:CartPoleEnv",
        scenes=("rmm_envs.adapters.classic_control:CartPoleScene",),
        envs={
            "guarded": "rmm_envs.envs.driven_examples:cartpole_guarded",
            "parallel": "rmm_envs.envs.driven_examples:cartpole_parallel",
        },
        driver="rmm_envs.envs.driven_examples:TargetTask",
        safe_default="rmm_envs.envs.driven:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        pages=(
            DocPage(
                "environments/driven_examples.md",
                "Simulators the project did not write, guarded",
                ("guarded", "parallel"),
            ),
        ),
        view="rmm_envs.views.pole:cartpole_view",
    )


def inverted_pendulum() -> SystemSpec:
    return SystemSpec(
        name="InvertedPendulum",
        blurb="Gymnasium's MuJoCo InvertedPendulum-v5 under the same target task (see the CartPole page)",
        dynamics="gymnasium.envs.mujoco.inverted_pendulum_v5:InvertedPendulumEnv",
        scenes=("rmm_envs.adapters.mujoco_envs:MujocoScene",),
        envs={
            "guarded": "rmm_envs.envs.driven_examples:inverted_pendulum_guarded",
            "parallel": "rmm_envs.envs.driven_examples:inverted_pendulum_parallel",
        },
        driver="rmm_envs.envs.driven_examples:TargetTask",
        safe_default="rmm_envs.envs.driven:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        extra="mujoco",
        view="rmm_envs.views.pole:pendulum_view",
    )


def systems() -> tuple[SystemSpec, ...]:
    """The built-in systems, in the order of the table."""
    return (dubins4d(), dubins4d_map(), dubins3d_maze(), quadrotor_room(), cartpole(), inverted_pendulum())
