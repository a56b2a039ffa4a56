"""The quadrotor flown through its controller: :class:`ClosedLoopQuadrotor`, the dynamics whose
control is the command (:mod:`rmm_envs.systems.quadrotor.control`), batched for the risk labels,
and its compiled loop over paths.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from rmm_envs.systems.quadrotor.body import Quadrotor
from rmm_envs.systems.quadrotor.control import (
    CommandController,
    body_packed,
    body_step,
    command_wrench,
    command_wrenches,
)

njit: Callable[..., Any] | None
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency
    njit = None

__all__ = ["ClosedLoopQuadrotor"]


def _closed_loop_paths(states, cmds, k, b, per_segment, out):
    """Every path of :meth:`ClosedLoopQuadrotor.propagate`: ``out`` (N, S, 13), ``out[:, 0]`` the
    starts; each later point after ``per_segment`` steps of controller then body."""
    u = np.empty(4)
    cur = np.empty(13)
    nxt = np.empty(13)
    for i in range(states.shape[0]):
        for j in range(13):
            cur[j] = states[i, j]
            out[i, 0, j] = cur[j]
        for p in range(1, out.shape[1]):
            for _ in range(per_segment):
                command_wrench(cur, cmds[i], k, u)
                body_step(cur, u, b, nxt)
                cur, nxt = nxt, cur
            for j in range(13):
                out[i, p, j] = cur[j]
    return out


if njit is not None:  # one source: the compiled loop runs this very function
    _closed_loop_paths = njit(cache=True)(_closed_loop_paths)


@dataclass(frozen=True)
class ClosedLoopQuadrotor:
    """The body flown through the controller: the dynamics whose control is the command.

    ``propagate`` holds each command for the branch and, at every physics step, turns it into
    thrust and moments with :func:`command_wrenches` and advances the batched
    :class:`~rmm_envs.systems.quadrotor.body.Quadrotor` (which reproduces PyBullet's integrator) by
    one step; segments are whole physics steps as there (``ceil(segment / dt)``).
    """

    controller: CommandController = CommandController()
    state_dim: ClassVar[int] = 13
    control_dim: ClassVar[int] = 4

    @property
    def body(self) -> Quadrotor:
        return Quadrotor(self.controller.params)

    @property
    def control_low(self) -> np.ndarray:
        return np.array(self.controller.command_low)

    @property
    def control_high(self) -> np.ndarray:
        return np.array(self.controller.command_high)

    def sample_controls(self, rng: np.random.Generator, n: int) -> np.ndarray:
        return rng.uniform(self.control_low, self.control_high, size=(n, 4))

    def propagate(self, states, commands, duration: float, n_steps: int) -> np.ndarray:
        body = self.body
        states, cmds = body.check_propagate(states, commands, duration, n_steps, self.control_low, self.control_high)
        per_segment = body.segment_steps(duration, n_steps)
        out = np.empty((states.shape[0], int(n_steps), 13))
        return _closed_loop_paths(
            np.ascontiguousarray(states),
            np.ascontiguousarray(cmds),
            self.controller.packed,
            body_packed(self.controller.params),
            per_segment,
            out,
        )

    def propagate_numpy(self, states, commands, duration: float, n_steps: int) -> np.ndarray:
        """The same paths through the numpy :meth:`Quadrotor.step
        <rmm_envs.systems.quadrotor.body.Quadrotor.step>` (the reference the compiled loop is pinned to)."""
        body = self.body
        states, cmds = body.check_propagate(states, commands, duration, n_steps, self.control_low, self.control_high)
        per_segment = body.segment_steps(duration, n_steps)
        out = np.empty((states.shape[0], int(n_steps), 13))
        out[:, 0] = s = states
        for j in range(1, int(n_steps)):
            for _ in range(per_segment):
                s = body.step(s, command_wrenches(s, cmds, self.controller.packed))
            out[:, j] = s
        return out
