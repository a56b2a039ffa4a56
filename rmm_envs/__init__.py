"""rmm_envs: environments, risk labelling and datasets for learned risk metric maps.

Importing the package registers the Gymnasium environments:

* ``Dubins4DCircles-v0``: Dubins4D among circles, blocking fixed-step (guardian action); also
  a native vector env, ``gym.make_vec("Dubins4DCircles-v0", num_envs=N)`` (numpy arrays,
  :mod:`rmm_envs.envs.dubins4d_vector`).
* ``Dubins4DParallel-v0``: the same, non-blocking (the guardian's compute time passes).
* ``Dubins4DMap-v0``, ``Dubins4DMapParallel-v0``: the same world on a map of your own (circles,
  polygons, walls from JSON; rays and collisions by pymunk, extra ``map``).
* ``Dubins3DMaze-v0``: a constant-speed Dubins car in procedurally generated mazes.
* ``Dubins3DMazeGuarded-v0``: that car driven to a goal cell by a reckless driver, a guardian
  may take over the turn rate (blocking, fixed step).
* ``Dubins3DMazeParallel-v0``: the same, non-blocking (the guardian's compute time passes).
* ``QuadrotorRoom-v0``: a quadrotor in procedurally generated rooms (PyBullet; extra ``quadrotor``).
* ``QuadrotorRoomGuarded-v0``: that quadrotor flown through waypoints by a reckless pilot on a
  cascaded controller, a guardian may take over the velocity command (blocking, fixed step).
* ``QuadrotorRoomParallel-v0``: the same, non-blocking (the guardian's compute time passes).
* ``CartPoleGuarded-v0``, ``InvertedPendulumGuarded-v0`` and their non-blocking twins
  ``CartPoleParallel-v0``, ``InvertedPendulumParallel-v0``: Gymnasium's CartPole and MuJoCo
  InvertedPendulum driven to a target by a reckless driver (:mod:`rmm_envs.envs.driven_examples`,
  built with :func:`rmm_envs.envs.driven.guarded`).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

import gymnasium as gym

try:
    __version__ = version("rmm-envs")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

#: The envs offering the parallel-autonomy contract (a built-in driver and a guardian action):
#: every registered env but the two plain-control ones, ``Dubins3DMaze-v0`` and ``QuadrotorRoom-v0``.
GUARDIAN_ENV_IDS = ("Dubins4DCircles-v0", "Dubins4DParallel-v0", "Dubins4DMap-v0", "Dubins4DMapParallel-v0",
                    "Dubins3DMazeGuarded-v0", "Dubins3DMazeParallel-v0", "QuadrotorRoomGuarded-v0",
                    "QuadrotorRoomParallel-v0")
ENV_IDS = ("Dubins4DCircles-v0", "Dubins4DParallel-v0", "Dubins4DMap-v0", "Dubins4DMapParallel-v0", "Dubins3DMaze-v0", "Dubins3DMazeGuarded-v0", "Dubins3DMazeParallel-v0",
           "QuadrotorRoom-v0", "QuadrotorRoomGuarded-v0", "QuadrotorRoomParallel-v0")


def _register() -> None:
    specs = {
        "Dubins4DCircles-v0": "rmm_envs.envs.dubins4d:Dubins4DCirclesEnv",
        "Dubins4DParallel-v0": "rmm_envs.envs.dubins4d:make_parallel_env",
        "Dubins4DMap-v0": "rmm_envs.envs.dubins4d_map:Dubins4DMapEnv",
        "Dubins4DMapParallel-v0": "rmm_envs.envs.dubins4d_map:make_parallel_env",
        "Dubins3DMaze-v0": "rmm_envs.envs.dubins3d_maze:Dubins3DMazeEnv",
        "Dubins3DMazeGuarded-v0": "rmm_envs.envs.dubins3d_maze_parallel:Dubins3DMazeGuardedEnv",
        "Dubins3DMazeParallel-v0": "rmm_envs.envs.dubins3d_maze_parallel:make_parallel_env",
        "QuadrotorRoom-v0": "rmm_envs.envs.quadrotor_room:QuadrotorRoomEnv",
        "QuadrotorRoomGuarded-v0": "rmm_envs.envs.quadrotor_room_parallel:QuadrotorRoomGuardedEnv",
        "QuadrotorRoomParallel-v0": "rmm_envs.envs.quadrotor_room_parallel:make_parallel_env",
    }
    vector_specs = {"Dubins4DCircles-v0": "rmm_envs.envs.dubins4d_vector:Dubins4DCirclesVectorEnv"}
    for env_id, entry in specs.items():
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point=entry, vector_entry_point=vector_specs.get(env_id),
                         disable_env_checker=False)


_register()

# the guarded envs around simulators the project did not write (rmm_envs.envs.driven_examples)
from rmm_envs.envs.driven_examples import register as _register_driven  # noqa: E402

DRIVEN_ENV_IDS = _register_driven()
GUARDIAN_ENV_IDS += DRIVEN_ENV_IDS
ENV_IDS += DRIVEN_ENV_IDS

__all__ = ["DRIVEN_ENV_IDS", "ENV_IDS", "GUARDIAN_ENV_IDS", "__version__"]
