"""The quadrotor in one room: :class:`QuadrotorScene`."""

from __future__ import annotations

import numpy as np

from rmm_envs.scenes.base import SceneBase
from rmm_envs.systems.quadrotor import Quadrotor, QuadrotorParams
from rmm_envs.worlds.room_collision import RoomCollision
from rmm_envs.worlds.rooms import Room

__all__ = ["QuadrotorScene"]


class QuadrotorScene(SceneBase):
    """The quadrotor in one room: the :class:`rmm_envs.risk.RiskScene` of ``QuadrotorRoom-v0``,
    for fast labelling.

    Propagation is the batched numpy integrator (:class:`rmm_envs.systems.Quadrotor`, which
    reproduces PyBullet's, built from the env's :class:`~rmm_envs.systems.quadrotor.QuadrotorParams`
    so damping and every other parameter agree), failure is the analytic room collision at the
    path's states (as the original checked its 8 path states).  Observations come from the env's
    PyBullet rays (``QuadrotorRoomEnv.observe_states``).  PyBullet stays the environment's truth;
    the tests compare the two.
    """

    state_dim = 13

    def __init__(self, room: Room, params: QuadrotorParams) -> None:
        self.room = room
        self.system = Quadrotor(params)
        self.collision = RoomCollision(room)

    def state_failed(self, states):
        return self.collision.states_failed(np.asarray(states, float))

    def path_failed(self, paths):
        paths = np.asarray(paths, float)
        return self.collision.states_failed(paths.reshape(-1, 13)).reshape(paths.shape[:2]).any(axis=1)
