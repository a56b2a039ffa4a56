"""What the guarded quadrotor senses: its observation's layout, the rays' directions, and the
dataset hooks that observe arbitrary states as the env observes its own."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.autonomy import ObservationLayout
from rmm_envs.envs.base import rejection_sample, state_rows
from rmm_envs.systems.quadrotor.control import heading_of
from rmm_envs.systems.quadrotor.rotations import quat_from_euler, quat_to_rot, unit_quaternion_rows

__all__ = ["N_RAYS", "QuadrotorDatasetHooks", "observation_layout"]

N_RAYS = 8
_CONTACT_MARGIN = 0.05  # m added to the travel bound before contact queries are skipped


def observation_layout() -> ObservationLayout:
    """The named slices of the observation table above."""
    return ObservationLayout.of(
        ("rays", N_RAYS),
        ("rays_vertical", 2),
        ("orientation", 4),
        ("velocity", 3),
        ("angular_velocity", 3),
        ("goal_offset", 3),
        ray_angles=[k * math.pi / 4 for k in range(N_RAYS)],
    )


_LAYOUT = observation_layout()
_RANGES = slice(_LAYOUT["rays"].start, _LAYOUT["rays_vertical"].stop)  # every ray, horizontal then vertical
_QUAT, _VEL, _RATES, _GOAL = (_LAYOUT[f] for f in ("orientation", "velocity", "angular_velocity", "goal_offset"))


_DIRS = np.array(
    [[math.cos(k * math.pi / 4), math.sin(k * math.pi / 4), 0.0] for k in range(N_RAYS)]
    + [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]
)


def _heading_frame(q, vectors) -> np.ndarray:
    """World vectors ``(N, 3)`` in the heading frames of quaternions ``(N, 4)``."""
    psi = heading_of(q)
    c, s = np.cos(psi), np.sin(psi)
    v = np.asarray(vectors, float)
    return np.column_stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1], v[:, 2]])


class QuadrotorDatasetHooks:
    """``sample_states`` and ``observe_states`` of
    :class:`rmm_envs.systems.quadrotor.guarded.QuadrotorRoomGuardedEnv` (it sets ``room``,
    ``scene``, ``goal`` and the PyBullet body its rays are cast from)."""

    goal: np.ndarray
    room: Any
    scene: Any
    require_episode: Callable[[], None]
    get_state: Callable[[], np.ndarray]
    set_state: Callable[[np.ndarray], None]
    rays: Callable[[], np.ndarray]

    def _features(self, states, rays) -> np.ndarray:
        st = np.atleast_2d(states)
        n = st.shape[0]
        R = quat_to_rot(st[:, 3:7])
        out = np.empty((n, _LAYOUT.size), dtype=np.float32)
        out[:, _RANGES] = rays
        out[:, _QUAT] = st[:, 3:7]
        out[:, _VEL] = _heading_frame(st[:, 3:7], st[:, 7:10])
        out[:, _RATES] = np.einsum("nji,nj->ni", R, st[:, 10:13])
        out[:, _GOAL] = _heading_frame(st[:, 3:7], self.goal[None, :] - st[:, :3])
        return out

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Flight states of the current room (see "Risk labelling" above)."""
        self.require_episode()
        room = self.room
        assert room is not None and self.scene is not None  # require_episode raised otherwise
        cells = np.argwhere(room.footprint)

        def draw(r, k):
            ij = cells[r.integers(len(cells), size=k)]
            xy = room.origin + (ij + r.uniform(0, 1, (k, 2))) * room.cell
            q = quat_from_euler(r.uniform(-0.3, 0.3, k), r.uniform(-0.3, 0.3, k), r.uniform(-np.pi, np.pi, k))
            psi = heading_of(q)
            vf, vl = r.uniform(-2, 2, k), r.uniform(-2, 2, k)
            v = np.column_stack(
                [np.cos(psi) * vf - np.sin(psi) * vl, np.sin(psi) * vf + np.cos(psi) * vl, r.uniform(-1, 1, k)]
            )
            return np.column_stack([xy, r.uniform(0.2, 3.0, k), q, v, r.uniform(-1, 1, (k, 3))])

        return rejection_sample(
            rng, n, 13, draw, self.scene.collision.states_failed, "quadrotor flight states clear of the room"
        )

    def observe_states(self, states, rng=None) -> np.ndarray:
        """This env's observation of states ``(N, 13)`` in the current episode (PyBullet rays; the
        env's state is restored); ``rng`` is unused."""
        self.require_episode()
        st = unit_quaternion_rows(state_rows(states, 13))
        keep = self.get_state()
        rays = np.empty((st.shape[0], _RANGES.stop - _RANGES.start))
        for i, row in enumerate(st):
            self.set_state(row)
            rays[i] = self.rays()
        self.set_state(keep)
        return self._features(st, rays)
