"""The quadrotor in one room: :class:`QuadrotorScene`."""

from __future__ import annotations

import numpy as np

from rmm_envs.scenes.base import SceneBase
from rmm_envs.scenes.branch_kernels import quadrotor_command_branches
from rmm_envs.systems.quadrotor.body import Quadrotor, QuadrotorParams
from rmm_envs.systems.quadrotor.closed_loop import ClosedLoopQuadrotor
from rmm_envs.systems.quadrotor.control import CommandController, body_packed
from rmm_envs.systems.quadrotor.room_collision import RoomCollision
from rmm_envs.systems.quadrotor.room_kernels import room_states_failed
from rmm_envs.systems.quadrotor.rooms import Room

__all__ = ["QuadrotorCommandScene", "QuadrotorScene"]


class QuadrotorScene(SceneBase):
    """The quadrotor in one room: the :class:`rmm_envs.risk.RiskScene` of ``QuadrotorRoom-v0``,
    for fast labelling.

    Propagation is the batched numpy integrator (:class:`rmm_envs.systems.quadrotor.body.Quadrotor`, which
    reproduces PyBullet's, built from the env's :class:`~rmm_envs.systems.quadrotor.body.QuadrotorParams`
    so damping and every other parameter agree), failure is the analytic room collision at the
    path's states (as the original checked its 8 path states).  Observations come from the env's
    PyBullet rays (``QuadrotorRoomEnv.observe_states``).  PyBullet stays the environment's truth;
    the tests compare the two.
    """

    state_dim = 13

    def __init__(self, room: Room, params: QuadrotorParams) -> None:
        self.room = room
        self.dynamics = Quadrotor(params)
        self.collision = RoomCollision(room)

    def state_failed(self, states):
        return self.collision.states_failed(np.asarray(states, float))

    def path_failed(self, paths):
        paths = np.asarray(paths, float)
        return self.collision.states_failed(paths.reshape(-1, 13)).reshape(paths.shape[:2]).any(axis=1)

    def _compiled_room(self) -> bool:
        """Whether ``path_failed`` is this class's room test (not a subclass's), so the compiled
        room test (:mod:`rmm_envs.systems.quadrotor.room_kernels`, the same bits) may stand in for it."""
        return type(self.collision) is RoomCollision and type(self).path_failed is QuadrotorScene.path_failed

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``path_failed(propagate(...))`` and the paths' last states, the path states tested by the
        compiled room test (:func:`~rmm_envs.systems.quadrotor.room_kernels.room_states_failed`, the same bits)."""
        if not self._compiled_room() or type(self).propagate is not SceneBase.propagate:
            return super().propagate_failed(states, controls, duration, n_steps)
        paths = self.propagate(states, controls, duration, n_steps)
        flat = np.ascontiguousarray(paths.reshape(-1, 13))
        failed = room_states_failed(flat, *self.collision.kernel_args(), np.empty(flat.shape[0], dtype=bool))  # type: ignore[call-arg]
        return failed.reshape(paths.shape[:2]).any(axis=1), paths[:, -1]


class QuadrotorCommandScene(QuadrotorScene):
    """The quadrotor flown through its cascaded controller in one room: the
    :class:`rmm_envs.risk.RiskScene` of ``QuadrotorRoomGuarded-v0`` / ``QuadrotorRoomParallel-v0``.

    The control is the *command* ``(v_forward, v_left, v_up, yaw_rate)``
    (:mod:`rmm_envs.systems.quadrotor.control`), so the estimator's uniform controls are random
    bounded commands, each held for one tree level, to a controller that keeps the body
    flying: the label is the risk of flying on at random, not of tumbling under random thrust
    and moments (:class:`QuadrotorScene`, the paper's labelling of ``QuadrotorRoom-v0``).
    Failure is the same analytic room collision at the path's states.
    """

    def __init__(self, room: Room, controller: CommandController) -> None:
        super().__init__(room, controller.params)
        self.dynamics = ClosedLoopQuadrotor(controller)

    def propagate_failed(self, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
        """``path_failed(propagate(...))`` and the paths' last states in one compiled loop
        (:func:`~rmm_envs.scenes.branch_kernels.quadrotor_command_branches`, the same bits), which
        stops a branch at its first failing point: a failed branch's ``ends`` row is that point."""
        dyn = self.dynamics
        if (
            not self._compiled_room()
            or type(self).propagate is not SceneBase.propagate
            or type(dyn) is not ClosedLoopQuadrotor
        ):
            return super().propagate_failed(states, controls, duration, n_steps)
        body = dyn.body
        states, cmds = body.check_propagate(states, controls, duration, n_steps, dyn.control_low, dyn.control_high)
        failed, ends = np.empty(states.shape[0], dtype=bool), np.empty((states.shape[0], 13))
        quadrotor_command_branches(
            np.ascontiguousarray(states),
            np.ascontiguousarray(cmds),
            dyn.controller.packed,
            body_packed(dyn.controller.params),
            body.segment_steps(duration, n_steps),
            int(n_steps),
            self.collision.kernel_args(),
            failed,
            ends,
        )
        return failed, ends
