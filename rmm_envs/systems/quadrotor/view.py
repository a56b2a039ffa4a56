"""The quadrotor's two views: from above (x, y) and from the side (x, z), side by side.

Both are 2-D projections of the state and of the room's boxes (walls, objects), computed once
per episode; no PyBullet rendering.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import ImageDraw

from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_envs.views.base import BODY_OUTLINE, DRIVER, GOAL, GUARDIAN, LIGHT, View, Window, convex_hull
from rmm_envs.views.text import font, text_size

__all__ = ["QuadrotorView", "quadrotor_view"]

WALL_FILL = (90, 90, 90)
OBJECT_FILL = (222, 160, 110)
OBJECT_EDGE = (150, 90, 40)
FLOOR = (120, 120, 120)
BODY_RADIUS = 0.304  # the body's bounding sphere (m)


@dataclass
class RoomOutlines:
    """The room projected once: per view, wall polygons and object polygons (pixels); the goal,
    its radius and the waypoints (world)."""

    top_walls: list
    top_objects: list
    side_walls: list
    side_objects: list
    goal: np.ndarray
    goal_radius: float
    waypoints: np.ndarray
    floor_y: float


def _rotate(points: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``R p`` of each row (elementwise products and sums, no BLAS: for pictures only)."""
    return (points[:, None, :] * R[None, :, :]).sum(axis=2)


def _shape_points(obj: dict) -> np.ndarray:
    """Points ``(P, 3)`` whose convex hull is the shape (its corners, or its rims sampled)."""
    pos = np.asarray(obj["pos"], float)
    R = quat_to_rot(np.asarray(obj["quat"], float))
    size = np.asarray(obj["size"], float)
    if obj["shape"] == "box":
        corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float) * size
        return pos + _rotate(corners, R)
    if obj["shape"] == "cylinder":
        r, length = float(size[0]), float(size[1])
        a = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        rim = np.column_stack([r * np.cos(a), r * np.sin(a), np.zeros_like(a)])
        local = np.vstack([rim + [0, 0, length / 2], rim - [0, 0, length / 2]])
        return pos + _rotate(local, R)
    r = float(size[0])  # a sphere: its outline is a circle in every projection
    a = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = np.column_stack([np.cos(a), np.sin(a)]) * r
    z = np.zeros_like(a)
    return pos + np.vstack(
        [np.column_stack([ring, z]), np.column_stack([ring[:, 0], z, ring[:, 1]]), np.column_stack([z, ring])]
    )


class QuadrotorView(View):
    """``QuadrotorRoomGuarded-v0`` / ``...Parallel-v0``: left, the room from above (walls dark,
    objects by their outline); right, from the side along ``+y`` (the floor, the wall height,
    objects); both at ``size x size``, the goal green and the pilot's waypoints ringed.

    State ``(x, y, z, qx, qy, qz, qw, vx, vy, vz, wx, wy, wz)``."""

    def __init__(self, size: int = 512) -> None:
        self.panel = int(size)
        self.width, self.height = 2 * self.panel, self.panel
        self.top = Window.square(0.0, 0.0, 5.0, self.panel)
        self.side = Window.square(0.0, 0.0, 5.0, self.panel, left=self.panel)

    def world(self, env) -> RoomOutlines:
        u = env.unwrapped
        priv = u.privileged()
        room = priv["room"]
        lo, hi = room.bounds()
        pad = 0.3
        cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
        half = max(hi[0] - lo[0], hi[1] - lo[1]) / 2 + pad
        self.top = Window.square(float(cx), float(cy), float(half), self.panel)
        # the side view: x as above; z from just below the floor to above the walls and waypoints,
        # stretched (at most 3x) so that a low room fills the panel
        wps = np.asarray(priv.get("waypoints", np.zeros((0, 3))), float).reshape(-1, 3)
        ztop = 1.15 * max(float(hi[2]), float(wps[:, 2].max()) if len(wps) else 0.0, 1.0)
        span = max(ztop * 1.1, 2 * half / 3)
        self.side = Window(
            float(cx - half), float(cx + half), -0.05 * span, 0.95 * span, self.panel, self.panel, left=self.panel
        )
        top_walls, side_walls = [], []
        for c in np.asarray(room.walls, float):
            a, b = c[:3] - c[3:], c[:3] + c[3:]
            top_walls.append(self.top.pixels([[a[0], a[1]], [b[0], a[1]], [b[0], b[1]], [a[0], b[1]]]))
            side_walls.append(self.side.pixels([[a[0], a[2]], [b[0], a[2]], [b[0], b[2]], [a[0], b[2]]]))
        top_objects, side_objects = [], []
        for obj in sorted(room.objects, key=lambda o: float(o["pos"][1]), reverse=True):  # far ones first (side)
            pts = _shape_points(obj)
            top_objects.append(self.top.pixels(convex_hull(pts[:, :2])))
            side_objects.append(self.side.pixels(convex_hull(pts[:, [0, 2]])))
        goal = np.asarray(priv["goal"], float)
        return RoomOutlines(
            top_walls,
            top_objects,
            side_walls,
            side_objects,
            goal,
            float(getattr(u, "goal_radius", 0.5)),
            np.asarray(priv.get("waypoints", goal[None, :]), float).reshape(-1, 3),
            self.side.px(0.0, 0.0)[1],
        )

    def draw_static(self, draw: ImageDraw.ImageDraw, world: RoomOutlines) -> None:
        def poly(p, **kw):
            draw.polygon([tuple(q) for q in p.tolist()], **kw)

        for p in world.top_objects:
            poly(p, fill=OBJECT_FILL, outline=OBJECT_EDGE)
        for p in world.top_walls:
            poly(p, fill=WALL_FILL)
        for p in world.side_walls:
            poly(p, outline=LIGHT)
        for p in world.side_objects:
            poly(p, fill=OBJECT_FILL, outline=OBJECT_EDGE)
        draw.line([(self.panel, world.floor_y), (2 * self.panel, world.floor_y)], fill=FLOOR, width=3)
        draw.line([(self.panel, 0), (self.panel, self.panel)], fill=BODY_OUTLINE, width=2)  # between the panels
        for w in world.waypoints[:-1]:
            self.top.disc(draw, w[0], w[1], world.goal_radius, outline=GOAL, width=2)
            self.side.disc(draw, w[0], w[2], world.goal_radius, outline=GOAL, width=2)
        g, r = world.goal, world.goal_radius
        self.top.disc(draw, g[0], g[1], r, fill=GOAL)
        self.side.disc(draw, g[0], g[2], r, fill=GOAL)
        f, m = font(text_size(self.panel)), round(self.panel / 64) + 2
        draw.text((m, m), "top (x, y)", fill=BODY_OUTLINE, font=f)
        draw.text((self.panel + m, m), "side (x, z)", fill=BODY_OUTLINE, font=f)

    def path_pixels(self, states: np.ndarray) -> np.ndarray:
        st = np.asarray(states, dtype=float).reshape(-1, 13)
        return np.stack([self.top.pixels(st[:, [0, 1]]), self.side.pixels(st[:, [0, 2]])], axis=1)

    def draw_body(self, draw: ImageDraw.ImageDraw, state: np.ndarray, active: bool, world: RoomOutlines) -> None:
        s = np.asarray(state, float)
        colour = GUARDIAN if active else DRIVER
        R = quat_to_rot(s[3:7])
        fwd, up = R[:, 0], R[:, 2]
        L = 2.0 * BODY_RADIUS
        self.top.disc(draw, s[0], s[1], BODY_RADIUS, fill=colour, outline=BODY_OUTLINE)
        draw.line(
            [self.top.px(s[0], s[1]), self.top.px(s[0] + L * fwd[0], s[1] + L * fwd[1])], fill=BODY_OUTLINE, width=3
        )
        # the side view: the rotor plane (body x axis) and the thrust axis (body z)
        self.side.disc(draw, s[0], s[2], BODY_RADIUS, fill=colour, outline=BODY_OUTLINE)
        arm = [self.side.px(s[0] - BODY_RADIUS * fwd[0], s[2] - BODY_RADIUS * fwd[2])]
        arm.append(self.side.px(s[0] + BODY_RADIUS * fwd[0], s[2] + BODY_RADIUS * fwd[2]))
        draw.line(arm, fill=BODY_OUTLINE, width=3)
        draw.line(
            [self.side.px(s[0], s[2]), self.side.px(s[0] + L * up[0], s[2] + L * up[2])], fill=BODY_OUTLINE, width=2
        )


def quadrotor_view(env, size: int) -> QuadrotorView:
    """The ``QuadrotorRoom`` system's view (its spec's ``view``)."""
    return QuadrotorView(size)
