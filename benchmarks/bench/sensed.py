"""What the guardian sensed, drawn over a replay's frame: its rays, as lines from the agent to where
each one ended, read from the observation and its layout.

The observation of an env of the package is an :class:`rmm_envs.autonomy.ObservationBox` whose
``layout`` names a ``"rays"`` field and gives each ray's angle from the heading
(``layout.ray_angles``).  A ray's value is the distance it measured; a value at the space's upper
bound is a ray that hit nothing within its range (drawn pale, without an end dot).  The agent's
position and heading come from the view's state (the true state the frame draws): a planar car
``(x, y, heading, ...)`` on a view with a ``window``, the quadrotor ``(x, y, z, quaternion, ...)``
on a view with ``top`` and ``side`` windows (its horizontal body-frame rays, projected on both).
Any other env, or an observation without rays, draws no ray.

Sizes scale with the panel's width (:func:`line_width`, :func:`text_size`) so that a frame stays
legible at 320 pixels wide.  Nothing here acts on the env.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from PIL import Image, ImageDraw

from rmm_envs.machine_independent import matvec
from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_envs.views.text import font

__all__ = ["HIT", "RAY", "RAY_FREE", "RaySegment", "draw_rays", "font", "line_width", "ray_segments", "text_size"]

#: a ray that hit something, its end dot, and a ray that hit nothing within its range
RAY = (0, 160, 160)
HIT = (0, 95, 95)
RAY_FREE = (170, 220, 220)

#: ``(window, (x0, y0), (x1, y1), hit)``: one ray on one panel, in the picture's pixels
RaySegment = tuple[object, tuple[float, float], tuple[float, float], bool]


def line_width(width: int) -> int:
    """Lines thick enough to see on a panel ``width`` pixels wide (2 px at 320 and 512)."""
    return max(2, round(width / 256))


def text_size(width: int) -> int:
    """The size of a side-by-side replay's headers on panels ``width`` pixels wide (15 px at 320,
    23 px at 512), a little larger than the frames' own text (:func:`rmm_envs.views.text.text_size`);
    :func:`font` is the frames' font."""
    return max(12, round(width / 22))


def _rays_of(layout, obs, high) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``(angles, distances, hit)`` of the observation's rays, or None when it has none."""
    if layout is None or obs is None or "rays" not in getattr(layout, "names", ()):
        return None
    angles = np.asarray(getattr(layout, "ray_angles", ()), dtype=float)
    o = np.asarray(obs, dtype=float).reshape(-1)
    if o.shape[0] != layout.size or angles.shape[0] != layout.size_of("rays"):
        return None
    sl = layout["rays"]
    d = o[sl]
    top = np.full(d.shape, np.inf) if high is None else np.asarray(high, dtype=float).reshape(-1)[sl]
    hit = np.isfinite(d) & (d < top)
    d = np.where(np.isfinite(d), d, np.where(np.isfinite(top), top, np.nan))
    keep = np.isfinite(d) & (d >= 0)
    return angles[keep], d[keep], hit[keep]


def ray_segments(view, state, obs, layout, high=None) -> list[RaySegment]:
    """The rays of ``obs`` (its ``layout``; ``high``: the space's upper bounds) from the agent at
    ``state``, on the panels of ``view``; empty when the view or the observation has no rays."""
    rays = _rays_of(layout, obs, high)
    if rays is None or state is None:
        return []
    angles, dist, hit = rays
    s = np.asarray(state, dtype=float).reshape(-1)
    window = getattr(view, "window", None)
    top, side = getattr(view, "top", None), getattr(view, "side", None)
    out: list[RaySegment] = []
    if window is not None and hasattr(window, "px") and s.shape[0] >= 3:  # a planar car
        x, y, th = float(s[0]), float(s[1]), float(s[2])
        start = window.px(x, y)
        for a, d, h in zip(angles.tolist(), dist.tolist(), hit.tolist(), strict=True):
            end = window.px(x + d * math.cos(th + a), y + d * math.sin(th + a))
            out.append((window, start, end, bool(h)))
    elif top is not None and side is not None and s.shape[0] >= 7:  # the quadrotor: body-frame rays
        R = np.asarray(quat_to_rot(s[3:7]), dtype=float)
        p = s[:3]
        for a, d, h in zip(angles.tolist(), dist.tolist(), hit.tolist(), strict=True):
            q = p + d * matvec(R, np.array([math.cos(a), math.sin(a), 0.0]))
            out.append((top, top.px(p[0], p[1]), top.px(q[0], q[1]), bool(h)))
            out.append((side, side.px(p[0], p[2]), side.px(q[0], q[2]), bool(h)))
    return out


def _box(window) -> tuple[int, int, int, int]:
    left, up = int(getattr(window, "left", 0)), int(getattr(window, "top", 0))
    return left, up, left + int(window.width), up + int(window.height)


def draw_rays(picture: Image.Image, segments: Sequence[RaySegment], width: int) -> None:
    """Draw ``segments`` on ``picture`` (in place), each clipped to its panel; ``width``: the
    panel's width in pixels, which sets the lines' thickness."""
    lw = line_width(width)
    dot = max(2, lw + 1)
    by_panel: dict[tuple[int, int, int, int], list[RaySegment]] = {}
    for seg in segments:
        by_panel.setdefault(_box(seg[0]), []).append(seg)
    for box, segs in by_panel.items():
        left, up = box[0], box[1]
        panel = picture.crop(box)
        d = ImageDraw.Draw(panel)
        for free in (True, False):  # the rays that hit nothing under those that did
            for _, a, b, hit in segs:
                if hit == free:
                    continue
                pts = [(a[0] - left, a[1] - up), (b[0] - left, b[1] - up)]
                d.line(pts, fill=RAY if hit else RAY_FREE, width=lw)
        for _, _, b, hit in segs:
            if hit:
                x, y = b[0] - left, b[1] - up
                d.ellipse((x - dot, y - dot, x + dot, y + dot), fill=HIT)
        picture.paste(panel, box[:2])
