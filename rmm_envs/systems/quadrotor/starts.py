"""Starts of a guarded quadrotor episode (room, body state, waypoints): drawn, given, or both.

The rules are stated in the "Starting state" section of :mod:`rmm_envs.systems.quadrotor.guarded`
(the env's spec); this module implements them for :class:`QuadrotorRoomStarts`, a mixin of
:class:`~rmm_envs.systems.quadrotor.guarded.QuadrotorRoomGuardedEnv`.  A drawn start keeps the
body's bounding sphere :data:`START_CLEARANCE` from the room, a drawn waypoint
:data:`WAYPOINT_CLEARANCE` and ``min_leg`` (horizontally) from the point before it; a given
state or waypoint must lie over the room's footprint, clear of it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from rmm_envs.envs.base import draw_until, option_vector
from rmm_envs.machine_independent import norm
from rmm_envs.systems.quadrotor.room_collision import BOUND, RoomCollision
from rmm_envs.systems.quadrotor.rooms import Room
from rmm_envs.systems.quadrotor.rotations import quat_from_euler

__all__ = ["START_CLEARANCE", "WAYPOINT_CLEARANCE", "QuadrotorRoomStarts"]

START_CLEARANCE = 0.2  # m between the bounding sphere and the room at a drawn start
WAYPOINT_CLEARANCE = 0.5  # m between the bounding sphere and the room at a drawn waypoint


class QuadrotorRoomStarts:
    """Start drawing for an env with ``np_random``, ``n_waypoints``, ``altitude``, ``min_leg``,
    ``_draw_room`` and ``_MAX_ROOM_DRAWS`` (those of the guarded quadrotor env)."""

    # declared only (no class attributes): the env this mixes into provides them
    np_random: np.random.Generator
    n_waypoints: int
    altitude: tuple[float, float]
    min_leg: float
    _MAX_ROOM_DRAWS: int
    _draw_room: Callable[[Room | dict | None], Room]

    def _point(self, rng, collision: RoomCollision, room: Room, clearance: float, after=None):
        cells = np.argwhere(room.footprint)

        def draw():
            ij = cells[rng.integers(len(cells))]
            xy = room.origin + (ij + rng.uniform(0, 1, 2)) * room.cell
            return np.array([xy[0], xy[1], rng.uniform(*self.altitude)])

        def ok(p):
            far = after is None or math.hypot(p[0] - after[0], p[1] - after[1]) >= self.min_leg
            return far and collision.clearance(p) >= clearance

        return draw_until(draw, ok, 200)

    def _plan(self, room: Room, state, waypoints):
        """``(state, waypoints)`` for ``room``, drawing what was not given; ``None`` if they
        cannot be placed."""
        rng, col = self.np_random, RoomCollision(room)
        if waypoints is not None and self._bad_waypoint(room, col, waypoints) is not None:
            return None
        if state is None:
            p = self._point(rng, col, room, START_CLEARANCE)
            if p is None:
                return None
            state = np.concatenate([p, quat_from_euler(0.0, 0.0, rng.uniform(-np.pi, np.pi)), np.zeros(6)])
        if waypoints is None:
            pts, last = [], state[:3]
            for _ in range(self.n_waypoints):
                last = self._point(rng, col, room, WAYPOINT_CLEARANCE, after=last)
                if last is None:
                    return None
                pts.append(last)
            waypoints = np.array(pts)
        return state, waypoints

    @staticmethod
    def _bad_waypoint(room: Room, collision: RoomCollision, waypoints):
        """The index of the first given waypoint the body cannot reach a goal at in ``room`` (not
        over its footprint, or its bounding sphere touching the floor, a wall or an object), or
        ``None``."""
        over = room.in_footprint(waypoints[:, :2])
        for i, w in enumerate(waypoints):
            if not over[i] or collision.clearance(w) <= 0:
                return i
        return None

    def draw_start(self, options: dict) -> tuple[Room, np.ndarray, np.ndarray]:
        """``(room, state, waypoints)`` of an episode from the checked reset ``options`` (``room``,
        ``state``, ``waypoints``), drawing what was not given; ``ValueError`` naming an option that
        cannot be met, ``RuntimeError`` if the env's own arguments leave no start placeable."""
        state = waypoints = None
        if "state" in options:
            state = option_vector(
                options["state"], 13, "state", " (position, quaternion xyzw, velocity, angular velocity)"
            )
            if abs(norm(state[3:7]) - 1) > 1e-6:
                raise ValueError(f"option 'state': the quaternion {state[3:7].tolist()} is not a unit quaternion")
        if "waypoints" in options:
            w = (
                np.asarray(options["waypoints"], dtype=float)
                if isinstance(options["waypoints"], (list, tuple, np.ndarray))
                else None
            )
            if w is None or w.ndim != 2 or w.shape[0] < 1 or w.shape[1] != 3 or not np.isfinite(w).all():
                raise ValueError(
                    f"option 'waypoints' must be a list of K >= 1 finite [x, y, z] points, got {options['waypoints']!r}"
                )
            low = np.nonzero(w[:, 2] <= BOUND)[0]
            if low.size:  # every room's floor is z = 0: no room to draw could hold it
                raise ValueError(
                    f"option 'waypoints': point {int(low[0])} {w[low[0]].tolist()} must lie higher than the "
                    f"body's bounding radius ({BOUND:.3f} m) above the floor, z = 0, in every room"
                )
            waypoints = w.copy()
        spec = options.get("room")
        if spec is not None and not isinstance(spec, (Room, dict)):
            raise ValueError(
                f"option 'room' must be a Room or a dict of generate_room arguments, got {type(spec).__name__}"
            )
        if isinstance(spec, Room) or state is not None:
            room = self._draw_room(spec)
            which = (
                "option 'room'"
                if isinstance(spec, Room)
                else "the room drawn from the seed (give 'room' too, or move it)"
            )
            if state is not None and not room.in_footprint(state[None, :2])[0]:
                raise ValueError(
                    f"option 'state': the body at {state[:3].tolist()} is not over the footprint of {which}"
                )
            if state is not None and RoomCollision(room).states_failed(state[None])[0]:
                raise ValueError(f"option 'state': the body at {state[:3].tolist()} is in contact with {which}")
            bad = None if waypoints is None else self._bad_waypoint(room, RoomCollision(room), waypoints)
            if bad is not None:
                assert waypoints is not None  # bad is only found among given waypoints
                raise ValueError(
                    f"option 'waypoints': point {bad} {waypoints[bad].tolist()} must lie over the "
                    f"footprint of {which} with the body's bounding sphere clear of it"
                )
            plan = self._plan(room, state, waypoints)
            if plan is None:
                given = " and ".join(f"'{k}'" for k in ("room", "state", "waypoints") if k in options)
                missing = [f"'{k}'" for k in ("state", "waypoints") if k not in options]
                raise ValueError(
                    f"could not place the {' and '.join(missing)} around option(s) {given} "
                    f"(200 draws each, min_leg={self.min_leg} m, altitude={self.altitude})"
                )
        else:
            plan = None
            for _ in range(self._MAX_ROOM_DRAWS):
                room = self._draw_room(spec)
                plan = self._plan(room, None, waypoints)
                if plan is not None:
                    break
            if plan is None and waypoints is not None:
                raise ValueError(
                    f"option 'waypoints' {waypoints.tolist()}: in none of {self._MAX_ROOM_DRAWS} rooms drawn "
                    "from the seed does every point lie over the footprint, clear of the room, with a start "
                    "placeable; give 'room' too or move them"
                )
            if plan is None:
                raise RuntimeError(
                    f"could not place a start and {self.n_waypoints} waypoints in "
                    f"{self._MAX_ROOM_DRAWS} rooms drawn (min_leg={self.min_leg} m, "
                    f"altitude={self.altitude}); lower min_leg or widen altitude"
                )
        state, waypoints = plan
        return room, state, waypoints
