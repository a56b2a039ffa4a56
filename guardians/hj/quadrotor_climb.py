"""The quadrotor ``hj``'s climb over what blocks the way (:mod:`rmm_guardians.hj.quadrotor`).

The horizontal value sees one altitude band; the rooms have no ceiling.  :class:`Climb` plans,
for a guardian that has been in control ``climb_after`` s, a 3-D way the value cannot see: brake
and rise in place to a cruise height ``z_c``, fly the straight line to the pilot's waypoint,
descend onto it.  ``z_c`` is the highest top of the walls and objects within the body's bounding
radius plus ``margin`` (and ``SETTLE``) of that line, plus the radius and ``margin`` (and
``SETTLE``), at least the body's and the waypoint's heights.  The plan is taken only when ``z_c``
is at most ``ceiling`` and the room's exact 3-D distance, sampled at most ``SAMPLE`` apart over
the rise (the braking run, at every height to ``z_c``), the line and the descent column, leaves
``margin`` round the body (the descent column: ``margin`` plus ``DESCEND``, the distance from the
waypoint it starts at): it never descends onto an obstacle.  Privileged: it reads the room.

The plan's phases: :class:`Climb`; the reasoning and the figures: docs/decisions/0013-hj-quadrotor.md.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rooms import bounding_radius
from rmm_guardians.hj.room import object_top, room_distance

__all__ = ["Climb", "ClimbPlan"]

SAMPLE = 0.1  # m between the points the path's clearance is checked at
SETTLE = 0.1  # m: the line starts within this of the braking point and of z_c
DESCEND = 0.2  # m: the descent starts within this of the waypoint (horizontally)
CRUISE = 1.5  # m/s: the most it flies at horizontally (the pilot's cruise speed)
HOLD_GAIN, LINE_GAIN, Z_GAIN = 1.0, 1.0, 1.5  # 1/s: position gains of the commands (damped with the loops')


class ClimbPlan:
    """A climb in progress: ``stop`` (x, y), the braking point it rises at, the cruise height
    ``z_c``, the ``waypoint`` (x, y, z) and the ``phase`` (``"rise"``, ``"line"``, ``"descend"``)."""

    def __init__(self, stop, z_c: float, waypoint) -> None:
        self.stop, self.z_c = (float(stop[0]), float(stop[1])), float(z_c)
        self.waypoint = tuple(float(v) for v in waypoint)
        self.phase = "rise"


class Climb:
    """Plans and flies climbs in ``room`` (the module docstring); ``speed``: the vertical speed it
    commands (m/s; horizontally it flies at most ``CRUISE``, the pilot's speed); ``k_v`` (1/s): the
    horizontal velocity loop's gain (a zero command stops the body ``v / k_v`` further on).

    A plan's phases: **rise** at the braking point (the horizontal command zero, so the lag stops
    the body ``v / k_v`` further on; the command holds that point, ``1 /s`` of position error at
    most 0.5 m/s, and climbs, ``1.5 /s`` of height error at most ``speed``, to ``z_c``); **line**
    (within ``SETTLE`` of the point and of ``z_c``: straight to the waypoint as the pilot flies,
    ``1 /s`` of distance at most its 1.5 m/s, holding ``z_c``); **descend** (within ``DESCEND``
    of the waypoint horizontally: down to its height at most ``speed``, still moving onto it;
    within ``SETTLE`` of it the climb is over and control goes back to the pilot).  Tops are exact
    (a rotated box: its centre's height plus the world-z extent of its half axes; a cylinder:
    ``|R_zz| L / 2 + r sqrt(1 - R_zz^2)``).  The braking point's *error* is commanded (its rate is
    the command under the lag): holding the point by its distance overshot it by 0.17 m after the
    pending lap.  Samples 0.1 m apart can miss 0.05 m between them and the loop tracks the line to
    a few centimetres, which ``margin`` covers."""

    def __init__(self, room, margin: float, ceiling: float, speed: float, k_v: float) -> None:
        self.room, self.margin, self.ceiling, self.speed, self.k_v = room, margin, ceiling, speed, k_v
        walls = np.asarray(room.walls, float).reshape(-1, 6)
        self._walls = walls
        self._wall_tops = walls[:, 2] + walls[:, 5]
        self._objects = [
            (
                float(o["pos"][0]),
                float(o["pos"][1]),
                bounding_radius(o["shape"], np.asarray(o["size"], float)),
                object_top(o),
            )
            for o in room.objects
        ]

    def top_near(self, a, b, reach: float) -> float:
        """The highest top of the walls and objects within ``reach`` (horizontally) of the segment
        from ``a`` to ``b`` (x, y); ``-inf`` if none."""
        top = -math.inf
        pts = _segment(a, b)
        if self._walls.size:
            w = self._walls
            qx = np.abs(pts[:, 0, None] - w[:, 0]) - w[:, 3]
            qy = np.abs(pts[:, 1, None] - w[:, 1]) - w[:, 4]
            ox, oy = np.maximum(qx, 0.0), np.maximum(qy, 0.0)
            near = (np.sqrt(ox * ox + oy * oy) <= reach + 0.5 * SAMPLE).any(axis=0)  # the samples are SAMPLE apart
            if near.any():
                top = float(self._wall_tops[near].max())
        for x, y, r, t in self._objects:
            if t > top and _to_segment(x, y, a, b) - r <= reach:
                top = t
        return top

    def plan(self, p0, p1, v1, z: float, waypoint) -> ClimbPlan | None:
        """A climb from the body at ``p0`` (x, y) and height ``z``, at ``p1`` with velocity ``v1``
        after the pending lap (braking there stops it ``v1 / k_v`` further on), to ``waypoint``;
        ``None`` when none is clear below ``ceiling``."""
        stop = (p1[0] + v1[0] / self.k_v, p1[1] + v1[1] / self.k_v)
        w = waypoint
        clear = BOUND + self.margin
        z_c = max(self.top_near(stop, w, clear + SETTLE) + clear + SETTLE, z, float(w[2]))
        if z_c > self.ceiling:
            return None
        rise = np.concatenate([_segment(p0, p1), _segment(p1, stop)])
        heights = np.linspace(z - SETTLE, z_c + SETTLE, _count(z_c - z + 2 * SETTLE))
        rise = np.column_stack([np.repeat(rise, len(heights), axis=0), np.tile(heights, len(rise))])
        line = _segment(stop, w)
        line = np.concatenate([np.column_stack([line, np.full(len(line), h)]) for h in (z_c, z_c + SETTLE)])
        if (room_distance(self.room, np.concatenate([rise, line])) - BOUND).min() <= self.margin:
            return None
        column = np.linspace(float(w[2]), z_c + SETTLE, _count(z_c + SETTLE - float(w[2])))
        column = np.column_stack([np.full(len(column), float(w[0])), np.full(len(column), float(w[1])), column])
        if (room_distance(self.room, column) - BOUND).min() <= self.margin + DESCEND:
            return None
        return ClimbPlan(stop, z_c, w)

    def command(
        self, plan: ClimbPlan, x: float, y: float, z: float, vx: float, vy: float
    ) -> tuple[float, float, float] | None:
        """The world-frame velocity command ``(vx, vy, vz)`` of ``plan`` at ``(x, y, z)`` with
        horizontal velocity ``(vx, vy)``, moving it to its next phase when due; ``None`` once it is
        over (within ``SETTLE`` of the waypoint's height at the end of the descent)."""
        wx, wy, wz = plan.waypoint
        if plan.phase == "rise" and z >= plan.z_c - SETTLE and math.hypot(x - plan.stop[0], y - plan.stop[1]) <= SETTLE:
            plan.phase = "line"
        if plan.phase == "line" and math.hypot(x - wx, y - wy) <= DESCEND:
            plan.phase = "descend"
        if plan.phase == "descend" and abs(z - wz) <= SETTLE:
            return None
        if plan.phase == "rise":  # move the point the body would stop at (p + v / k_v) to the braking point
            rx, ry = x + vx / self.k_v, y + vy / self.k_v  # (under the lag, its rate is the command: no overshoot)
            vx, vy, cap = HOLD_GAIN * (plan.stop[0] - rx), HOLD_GAIN * (plan.stop[1] - ry), 0.5
        else:  # toward the waypoint, as the pilot does
            vx, vy, cap = LINE_GAIN * (wx - x), LINE_GAIN * (wy - y), CRUISE
        n = math.hypot(vx, vy)
        if n > cap:
            vx, vy = vx * cap / n, vy * cap / n
        target = wz if plan.phase == "descend" else plan.z_c
        vz = min(max(Z_GAIN * (target - z), -self.speed), self.speed)
        return vx, vy, vz


def _count(length: float) -> int:
    return max(2, int(math.ceil(length / SAMPLE)) + 1)


def _segment(a, b) -> np.ndarray:
    """Points at most ``SAMPLE`` apart from ``a`` to ``b`` (x, y), both ends included."""
    t = np.linspace(0.0, 1.0, _count(math.hypot(float(b[0]) - float(a[0]), float(b[1]) - float(a[1]))))
    return np.column_stack(
        [float(a[0]) + t * (float(b[0]) - float(a[0])), float(a[1]) + t * (float(b[1]) - float(a[1]))]
    )


def _to_segment(x: float, y: float, a, b) -> float:
    """Distance from ``(x, y)`` to the segment from ``a`` to ``b``."""
    ax, ay, bx, by = float(a[0]), float(a[1]), float(b[0]), float(b[1])
    dx, dy = bx - ax, by - ay
    n2 = dx * dx + dy * dy
    t = 0.0 if n2 == 0.0 else min(max(((x - ax) * dx + (y - ay) * dy) / n2, 0.0), 1.0)
    return math.hypot(x - ax - t * dx, y - ay - t * dy)
