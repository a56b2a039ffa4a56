"""The reckless quadrotor pilot: straight at each waypoint, ignoring walls and objects.

:class:`WaypointPilot` flies the quadrotor through a list of waypoints (the last one is the
goal) by issuing *commands* to the cascaded controller
(:mod:`rmm_envs.systems.quadrotor.control`): ``(v_forward, v_left, v_up, yaw_rate)`` in the
body's heading frame, proportional to the offset to the current waypoint (limited to
``cruise_speed`` and ``climb_speed``), turning to look where it flies, each number clipped to
the command box.  A waypoint other than the last is passed within ``reach`` of it.  It is
deliberately careless (straight lines cross walls and meet objects); it is deterministic: all
the randomness of an episode is in its waypoints.  The command law in full: :class:`WaypointPilot`.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.quadrotor.control import yaw_of

__all__ = ["WaypointPilot"]


class WaypointPilot:
    """The command law.  From position ``p`` and yaw ``psi``, toward the current waypoint ``w``:

    * horizontal velocity ``gain * (w - p)_xy`` in the world frame, its norm limited to
      ``cruise_speed``, turned into the heading frame (by ``-psi``);
    * vertical velocity ``gain * (w - p)_z``, limited to ``climb_speed``;
    * yaw rate ``yaw_gain * wrap(bearing - psi)`` (limited by the command box), ``bearing`` the
      direction of ``(w - p)_xy``, so the body's forward ray looks where it flies; no turn within
      ``reach`` of the waypoint horizontally;
    * each number clipped to the command box.

    A waypoint other than the last is passed once the body is within ``reach`` of it (3-D
    distance), and the pilot turns to the next.

    Args:
    command_low, command_high: the command box (4 numbers each), the controller's.
    cruise_speed: horizontal speed limit, m/s (default 1.5).
    climb_speed: vertical speed limit, m/s (default 0.5).
    gain: velocity per metre of distance, 1/s (default 1.0: full speed from 1.5 m away).
    yaw_gain: yaw rate per radian of bearing error, 1/s (default 2.0).
    reach: distance at which a waypoint is passed, m (default 0.5).
    """

    def __init__(
        self,
        command_low,
        command_high,
        cruise_speed: float = 1.5,
        climb_speed: float = 0.5,
        gain: float = 1.0,
        yaw_gain: float = 2.0,
        reach: float = 0.5,
    ) -> None:
        for name, v in (
            ("cruise_speed", cruise_speed),
            ("climb_speed", climb_speed),
            ("gain", gain),
            ("yaw_gain", yaw_gain),
            ("reach", reach),
        ):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"{name} must be a finite number > 0, got {v!r}")
        self.low = np.asarray(command_low, dtype=float).reshape(4)
        self.high = np.asarray(command_high, dtype=float).reshape(4)
        self.cruise_speed, self.climb_speed = float(cruise_speed), float(climb_speed)
        self.gain, self.yaw_gain, self.reach = float(gain), float(yaw_gain), float(reach)
        self.waypoints = np.zeros((0, 3))
        self.index = 0

    def reset(self, waypoints) -> None:
        """Fly through ``waypoints`` ``(K >= 1, 3)`` from the first."""
        w = np.asarray(waypoints, dtype=float)
        if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 1 or not np.isfinite(w).all():
            raise ValueError(f"waypoints must be (K >= 1, 3) finite points, got shape {w.shape}")
        self.waypoints = w.copy()
        self.index = 0

    @property
    def target(self) -> np.ndarray:
        """The waypoint it flies to now."""
        return self.waypoints[self.index]

    def command(self, state) -> np.ndarray:
        """The command for body state ``state`` (13 numbers; advances past reached waypoints)."""
        s = np.asarray(state, dtype=float)
        x, y, z = s[0], s[1], s[2]
        while self.index < len(self.waypoints) - 1 and math.dist((x, y, z), self.waypoints[self.index]) < self.reach:
            self.index += 1
        wx, wy, wz = self.waypoints[self.index]
        dx, dy, dz = wx - x, wy - y, wz - z
        psi = yaw_of(s[3], s[4], s[5], s[6])
        vx, vy = self.gain * dx, self.gain * dy
        speed = math.hypot(vx, vy)
        if speed > self.cruise_speed:
            vx, vy = vx * self.cruise_speed / speed, vy * self.cruise_speed / speed
        vz = min(max(self.gain * dz, -self.climb_speed), self.climb_speed)
        c, sn = math.cos(psi), math.sin(psi)
        yaw_rate = 0.0
        if math.hypot(dx, dy) > self.reach:
            err = (math.atan2(dy, dx) - psi + math.pi) % (2 * math.pi) - math.pi
            yaw_rate = self.yaw_gain * err
        cmd = np.array([c * vx + sn * vy, -sn * vx + c * vy, vz, yaw_rate])
        return np.minimum(np.maximum(cmd, self.low), self.high)
