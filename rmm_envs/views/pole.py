"""A cart and pole seen from the front (:class:`CartAndPoleView`, drawn with a system's
:class:`PoleGeometry`: ``rmm_envs/systems/cartpole/view.py``, ``.../pendulum/view.py``), and the
fallback view of any other guarded env: its own ``render()`` frame."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from PIL import Image, ImageDraw

from rmm_envs.views.base import BODY_OUTLINE, DRIVER, GOAL, GUARDIAN, LIGHT, OBSTACLE, View, Window

__all__ = ["CartAndPoleView", "EnvFrameView", "PoleGeometry", "driver_target"]


@dataclass(frozen=True)
class PoleGeometry:
    """Where the cart position and pole angle sit in the true state, the pole's length (m), the
    track's ends ``|x| <= x_limit`` (CartPole fails beyond them; InvertedPendulum's rail stops
    the cart there) and the pole's failing angle ``|theta| > angle_limit``."""

    pos: int
    ang: int
    length: float
    x_limit: float
    angle_limit: float


class CartAndPoleView(View):
    """A cart on a track and its pole; the path is the pole's tip.  The track's ends (red) and
    the pole's failing angles (lines from the cart, drawn with the body) are the limits; no goal
    is drawn unless ``target`` (a callable returning the target's ``x``, asked at each episode's
    start) is given: :func:`driver_target` gives the built-in drivers' one."""

    def __init__(self, geometry: PoleGeometry, size: int = 512, target=None) -> None:
        self.g = geometry
        self.width = self.height = int(size)
        half = 1.2 * geometry.x_limit
        self.window = Window(-half, half, -0.6 * half, 1.4 * half, self.width, self.height)
        self.target = target

    def world(self, env) -> Any:
        return None if self.target is None else float(self.target())

    def draw_static(self, draw: ImageDraw.ImageDraw, world: Any) -> None:
        w, g = self.window, self.g
        draw.line([w.px(-g.x_limit, 0.0), w.px(g.x_limit, 0.0)], fill=LIGHT, width=4)
        for s in (-1, 1):
            w.rectangle(draw, (s * g.x_limit - 0.03, -0.15), (s * g.x_limit + 0.03, 0.15), fill=OBSTACLE)
        if world is not None:
            draw.line([w.px(world, -0.25), w.px(world, 0.0)], fill=GOAL, width=5)

    def _tips(self, st: np.ndarray) -> np.ndarray:
        x, th = st[:, self.g.pos], st[:, self.g.ang]
        return np.column_stack([x + self.g.length * np.sin(th), self.g.length * np.cos(th)])

    def path_pixels(self, states: np.ndarray) -> np.ndarray:
        st = np.atleast_2d(np.asarray(states, dtype=float))
        return self.window.pixels(self._tips(st))[:, None, :]

    def draw_body(self, draw: ImageDraw.ImageDraw, state: np.ndarray, active: bool, world: Any) -> None:
        w, g = self.window, self.g
        s = np.asarray(state, float)
        x = float(s[g.pos])
        colour = GUARDIAN if active else DRIVER
        for a in (-g.angle_limit, g.angle_limit):  # the failing angles
            end = w.px(x + g.length * np.sin(a), g.length * np.cos(a))
            draw.line([w.px(x, 0.0), end], fill=OBSTACLE, width=1)
        w.rectangle(draw, (x - 0.25, -0.08), (x + 0.25, 0.08), fill=colour, outline=BODY_OUTLINE)
        tip = self._tips(s[None, :])[0]
        draw.line([w.px(x, 0.0), w.px(tip[0], tip[1])], fill=BODY_OUTLINE, width=5)
        w.disc(draw, tip[0], tip[1], 0.04, fill=colour, outline=BODY_OUTLINE)


class EnvFrameView(View):
    """Any guarded env whose simulator renders (``render_mode="rgb_array"``): its own frame,
    captured at every step and scaled to ``size`` wide, framed in the colour of who controls.
    No path (the view knows no coordinates)."""

    captures = True

    def __init__(self, env, size: int = 512) -> None:
        u = env.unwrapped
        if getattr(u, "render_mode", None) != "rgb_array":
            raise ValueError(
                f"{type(u).__name__} has no view of its own, so its frames are its render() frames: make it with "
                f"render_mode='rgb_array', got render_mode={getattr(u, 'render_mode', None)!r}"
            )
        self.width = self.height = int(size)  # the height follows the env's frame, read at each episode's start

    def world(self, env) -> Any:
        h, w = np.asarray(env.unwrapped.render_frame()).shape[:2]
        self.height = max(int(round(h * self.width / w)), 1)
        return None

    def state(self, env) -> np.ndarray:
        """Nothing: the picture is the env's (a simulator of one's own need not offer a state's labels)."""
        return np.zeros(0)

    def capture(self, env) -> np.ndarray:
        return np.asarray(env.unwrapped.render_frame(), dtype=np.uint8)

    def paste(self, picture: Image.Image, frame: np.ndarray, active: bool) -> None:
        img = Image.fromarray(np.ascontiguousarray(frame[..., :3]))
        if img.size != (self.width, self.height):
            img = img.resize((self.width, self.height))
        picture.paste(img, (0, 0))
        ImageDraw.Draw(picture).rectangle(
            (0, 0, self.width - 1, self.height - 1), outline=GUARDIAN if active else DRIVER, width=6
        )


def driver_target(env) -> Callable[[], float] | None:
    """The goal a pole view draws: the guarded env's driver's ``target`` (a number, read at each
    episode's start, as the built-in ``CartPoleGuarded-v0`` / ``InvertedPendulumGuarded-v0``
    drivers pick a cart position per episode); ``None`` when the driver has none."""
    driver = getattr(env.unwrapped, "driver", None)
    if driver is None or not isinstance(getattr(driver, "target", None), int | float):
        return None
    return lambda: float(driver.target)
