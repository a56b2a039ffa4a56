"""The episode recorder: per-step state, who controlled and the guardian's signals, composed into frames.

``rec = EpisodeRecorder(env)``; after ``env.reset``: ``rec.begin()`` (reads the world, draws the
static layer once); after every ``env.step``: ``rec.record(info, guardian.signals())``; then
``rec.frames(every=K)`` yields ``(H, W, 3)`` uint8 frames.  A frame is the view's picture (the
path so far, blue the driver, orange the guardian; the body; the collision point) over a strip:
the frame's status line (its time and step, who controlled, the outcome), then, spanning the
episode, the guardian's intervals, one lane per group of signals, a cursor at the frame's time.
Text and strip grow with the panel (:mod:`rmm_envs.views.text`), so that a frame stays legible
at 320 pixels.  Frames may be asked in any order; in order each costs only the new path.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping

import numpy as np
from PIL import Image, ImageDraw

from rmm_envs.views.base import BACKGROUND, BODY_OUTLINE, COLLISION, DRIVER, GUARDIAN, LIGHT, View
from rmm_envs.views.select import view_for
from rmm_envs.views.text import MIN_TEXT, cut, draw_runs, fitted, font, text_size, text_width

__all__ = ["STRIP_HEIGHT", "EpisodeRecorder", "signal_groups"]

#: the strip's height in pixels (the frame's status line, the intervention lane and its caption,
#: then the signals' lanes) at the smallest text size (:data:`rmm_envs.views.text.MIN_TEXT`:
#: panels up to 392 pixels); it grows with the text
STRIP_HEIGHT = 132
PATH_WIDTH = 3
_MARGIN = 6  # the strip's left and right margin at the smallest text size
_LINE_COLOURS = ((60, 60, 60), (214, 39, 40), (148, 103, 189), (23, 190, 207))
_THRESHOLD = (120, 120, 120)
#: the colours of who controls and of an outcome, as text (darker than the path's, to read on white)
_WHO = {False: (22, 90, 140), True: (190, 80, 0)}
_OUTCOME = {"collision": COLLISION, "goal": (30, 120, 30)}


def signal_groups(keys) -> dict[str, list[str]]:
    """Signals sharing the part of their name before the first ``_`` share a lane and a scale
    (``risk`` and ``risk_threshold``; ``value`` and ``value_threshold``), in first-seen order."""
    groups: dict[str, list[str]] = {}
    for k in keys:
        groups.setdefault(k.split("_", 1)[0], []).append(k)
    return groups


class EpisodeRecorder:
    """Records one episode of ``env`` (blocking or non-blocking, built-in or built with
    :func:`rmm_envs.envs.any_env.guarded` / ``parallel``) and composes its frames.

    ``view``: the system's :class:`~rmm_envs.views.base.View` (default :func:`rmm_envs.views.view_for`);
    ``size``: the view's panel size in pixels; ``strip_height``: the strip's (0: no strip; default:
    :data:`STRIP_HEIGHT`, grown in proportion with the text).

    Text is drawn at :func:`rmm_envs.views.text.text_size` of the panel's side (the view's
    ``panel`` if it has one, else its width): capitals at least 10 pixels high, legible at 320.
    """

    def __init__(self, env, view: View | None = None, size: int = 512, strip_height: int | None = None) -> None:
        self.env = env
        self.view = view if view is not None else view_for(env, size)
        self._strip_height = None if strip_height is None else int(strip_height)
        self.static_draws = 0  #: how many times the static layer was drawn (once per episode)
        self._begun = False

    # ------------------------------------------------------------------ recording
    def begin(self) -> None:
        """Start an episode, after ``env.reset``: read the world, draw the static layer, record the start state."""
        v = self.view
        self.world = v.world(self.env)
        self._static = v.new_picture()
        v.draw_static(ImageDraw.Draw(self._static), self.world)
        self.static_draws += 1
        self.states: list[np.ndarray] = []
        self.active: list[bool] = []
        self.times: list[float] = []
        self.signals: list[dict[str, float]] = []
        self._captures: list[np.ndarray | None] = []
        self.outcome: str | None = None
        self._pix = np.zeros((0, 0, 2))
        self._trail: Image.Image | None = None
        self._trail_k = -1
        self._strip_key: tuple | None = None
        self._strip: Image.Image | None = None
        self._label_rows: list[tuple[int, int]] = []  # the strip's rows of signal labels (the cursor skips them)
        self._counted = 0
        self._begun = True
        self.add(v.state(self.env), False, 0.0, None, capture=v.capture(self.env))

    def record(self, info: Mapping | None = None, signals: Mapping[str, float] | None = None, active=None) -> None:
        """Record the step just taken: the state (read from the env), who controlled it
        (``active``, else ``info["active"]``, else the env's active-step count), its end time
        (``info["sim_time"]``, else the env's statistics), the outcome (``info["outcome"]``) and
        ``signals``: the guardian's signals of the decision that chose the step's action
        (plain floats, e.g. ``guardian.signals()``)."""
        info = {} if info is None else info
        stats = None
        if active is None and "active" in info:
            active = bool(info["active"])
        if active is None or "sim_time" not in info:
            stats = self.env.unwrapped.episode_statistics()
        if active is None:
            assert stats is not None
            n = int(stats["n_active_ctrl_env_steps"])
            active, self._counted = n > self._counted, n
        if "sim_time" in info:
            t = float(info["sim_time"])
        else:
            assert stats is not None  # read above when the info has no sim_time
            t = float(stats["cum_sim_time"])
        self.add(self.view.state(self.env), bool(active), t, signals, info.get("outcome"), self.view.capture(self.env))

    def add(
        self,
        state,
        active: bool,
        time: float,
        signals: Mapping[str, float] | None = None,
        outcome: str | None = None,
        capture: np.ndarray | None = None,
    ) -> None:
        """Record one step from its parts (the state after it, who controlled it, its end time,
        the decision's signals, the outcome if it ended the episode); :meth:`record` reads them
        from the env.  Also the way to draw a trajectory of one's own."""
        if not self._begun:
            raise RuntimeError("EpisodeRecorder.begin() must be called after env.reset(), before recording steps")
        self.states.append(np.asarray(state, dtype=float).copy())
        self.active.append(bool(active))
        self.times.append(float(time))
        self.signals.append({str(k): float(x) for k, x in (signals or {}).items()})
        self._captures.append(capture)
        if outcome is not None:
            self.outcome = str(outcome)

    @property
    def n_steps(self) -> int:
        """Steps recorded (the start state is frame 0; step ``k`` ends at frame ``k``)."""
        return len(self.states) - 1

    @property
    def active_steps(self) -> int:
        return sum(self.active[1:])

    def intervals(self) -> list[tuple[float, float]]:
        """The simulated-time intervals ``(start, end)`` the guardian controlled, merged."""
        out: list[tuple[float, float]] = []
        for k in range(1, len(self.states)):
            if self.active[k]:
                a, b = self.times[k - 1], self.times[k]
                if out and out[-1][1] == a:
                    out[-1] = (out[-1][0], b)
                else:
                    out.append((a, b))
        return out

    # ------------------------------------------------------------------ frames
    @property
    def text_px(self) -> int:
        """The font size of the frame's text, in pixels."""
        return text_size(getattr(self.view, "panel", self.view.width))

    @property
    def strip_height(self) -> int:
        """The strip's height in pixels."""
        if self._strip_height is not None:
            return self._strip_height
        return round(STRIP_HEIGHT * self.text_px / MIN_TEXT)

    def _u(self, n: float) -> int:
        """``n`` pixels at the smallest text size, at this frame's."""
        return max(int(n), round(n * self.text_px / MIN_TEXT))

    @property
    def _row_h(self) -> int:
        """The height of a row of text."""
        return round(1.45 * self.text_px)

    @property
    def status_rows(self) -> tuple[int, int]:
        """The frame's rows of its status line (the time, the step, who controlled, the outcome),
        top and bottom: the strip's first row, or the view's last one when there is no strip."""
        if self.strip_height > 0:
            return self.view.height, self.view.height + self._row_h
        return self.view.height - self._row_h - self._u(2), self.view.height - self._u(2)

    @property
    def lane_rows(self) -> tuple[int, int]:
        """The strip's rows of the intervention lane, top and bottom (the status line and the
        lane's caption above it)."""
        return 2 * self._row_h, 2 * self._row_h + round(0.8 * self.text_px)

    @property
    def frame_size(self) -> tuple[int, int]:
        """``(height, width)`` of every frame."""
        return self.view.height + self.strip_height, self.view.width

    def frames(self, every: int = 1) -> Iterator[np.ndarray]:
        """Frames ``0, every, 2 every, ...`` and always the last one."""
        last = self.n_steps
        ks = list(range(0, last + 1, max(int(every), 1)))
        if ks[-1] != last:
            ks.append(last)
        for k in ks:
            yield self.frame(k)

    def frame(self, k: int | None = None) -> np.ndarray:
        """The frame after step ``k`` (default: the last recorded), ``(H, W, 3)`` uint8."""
        if not self._begun:
            raise RuntimeError("EpisodeRecorder.begin() must be called after env.reset() before asking for frames")
        last = self.n_steps
        k = last if k is None else int(k)
        if not 0 <= k <= last:
            raise IndexError(f"frame {k} is not recorded: frames 0-{last}")
        v = self.view
        out = Image.new("RGB", (v.width, v.height + self.strip_height), BACKGROUND)
        capture = self._captures[k]
        if v.captures and capture is not None:
            v.paste(out, capture, self.active[k])
        else:
            out.paste(self._trail_to(k), (0, 0))
        draw = ImageDraw.Draw(out)
        if not v.captures:
            v.draw_body(draw, self.states[k], self.active[k], self.world)
        if k == last and self.outcome == "collision":
            for x, y in self._pixels()[k].tolist():
                draw.line([(x - 9, y - 9), (x + 9, y + 9)], fill=COLLISION, width=4)
                draw.line([(x - 9, y + 9), (x + 9, y - 9)], fill=COLLISION, width=4)
                draw.ellipse((x - 14, y - 14, x + 14, y + 14), outline=COLLISION, width=2)
        if self.strip_height > 0:
            out.paste(self._strip_image(), (0, v.height))
            x, top = self._time_x(self.times[k]), self.lane_rows[0]  # the cursor, clear of every text
            for a, b in [*self._label_rows, (self.strip_height, self.strip_height)]:  # rows a-b skipped
                if a > top:
                    draw.line([(x, v.height + top), (x, v.height + a - 1)], fill=BODY_OUTLINE, width=self._u(1))
                top = max(top, b + 1)
        self._draw_status(out, k)
        return np.asarray(out)

    def _draw_status(self, out: Image.Image, k: int) -> None:
        """The frame's status line (:attr:`status_rows`): the time, the step, who controlled, the
        outcome on the last frame; fitted to the view's width, on a pale backing over the view
        when there is no strip."""
        last, active = self.n_steps, self.active[k]
        runs = [
            (f"t {self.times[k]:.2f} s  step {k}/{last}  ", BODY_OUTLINE),
            ("guardian" if active else "driver", _WHO[active]),
        ]
        if k == last and self.outcome:
            runs.append((f"  {self.outcome}", _OUTCOME.get(self.outcome, BODY_OUTLINE)))
        m = self._u(_MARGIN)
        room, text = self.view.width - 2 * m, "".join(t for t, _ in runs)
        f = font(self.text_px)
        if text_width(text, f) > room:  # a small view: a smaller font, then the step left out
            f = fitted(text, self.text_px, room)
            if text_width(text, f) > room:
                runs[0] = (f"t {self.times[k]:.2f} s  ", BODY_OUTLINE)
        over_view = self.strip_height <= 0
        draw_runs(out, (m + self._u(3), self.status_rows[0] + self._u(1)), runs, f, backing=0.75 if over_view else 0)

    def _pixels(self) -> np.ndarray:
        n = len(self.states)
        have = self._pix.shape[0]
        if have < n:
            new = self.view.path_pixels(np.array(self.states[have:]))
            self._pix = new if have == 0 else np.concatenate([self._pix, new])
        return self._pix

    def _trail_to(self, k: int) -> Image.Image:
        """The static layer with the path up to state ``k`` drawn (kept and extended in order)."""
        if self._trail is None or k < self._trail_k:
            self._trail, self._trail_k = self._static.copy(), 0
        if k > self._trail_k:
            pix = self._pixels()
            draw = ImageDraw.Draw(self._trail)
            j = self._trail_k
            while j < k:  # runs of one colour, each one polyline per panel
                a = self.active[j + 1]
                e = j + 1
                while e < k and self.active[e + 1] == a:
                    e += 1
                colour = GUARDIAN if a else DRIVER
                for p in range(pix.shape[1]):
                    pts = [tuple(q) for q in pix[j : e + 1, p].tolist()]
                    draw.line(pts, fill=colour, width=PATH_WIDTH, joint="curve")
                j = e
            self._trail_k = k
        return self._trail

    # ------------------------------------------------------------------ the strip
    def _span(self) -> float:
        t = self.times[-1] if self.times else 0.0
        return t if t > 0 else 1.0

    def _time_x(self, t: float) -> float:
        m = self._u(_MARGIN)
        return m + (self.view.width - 2 * m) * min(max(t / self._span(), 0.0), 1.0)

    def _row(self, img: Image.Image, y: int, left: list[tuple[str, tuple]], right: str = "") -> None:
        """One line of text across the strip at ``y``: ``left``'s runs (text, colour) from the left
        margin, ``right`` against the right one, a gap between them; the font shrinks until both
        fit, and ``right`` is left out if they never do."""
        m, s = self._u(_MARGIN), self.text_px
        room = img.width - 2 * m - self._u(3)
        gap = "    " if right else ""
        both = "".join(t for t, _ in left) + gap + right
        f = fitted(both, s, room)
        if text_width(both, f) > room:
            right, f = "", fitted("".join(t for t, _ in left), s, room)
        if text_width("".join(t for t, _ in left), f) > room:
            left = [(cut("".join(t for t, _ in left), f, room), left[0][1])]
        draw_runs(img, (m + self._u(3), y), left, f)
        if right:
            draw_runs(img, (img.width - m - text_width(right, f), y), [(right, BODY_OUTLINE)], f)

    def _strip_image(self) -> Image.Image:
        """The strip over the steps recorded so far (drawn again only when steps were added)."""
        key = (len(self.states), self.outcome)
        if self._strip is not None and self._strip_key == key:
            return self._strip
        W, H = self.view.width, self.strip_height
        img = Image.new("RGB", (W, H), BACKGROUND)
        d = ImageDraw.Draw(img)
        m, lane = self._u(_MARGIN), self.lane_rows
        d.rectangle((m, lane[0], W - m, lane[1]), fill=(236, 236, 236))
        for a, b in self.intervals():
            xa, xb = self._time_x(a), self._time_x(b)
            d.rectangle((xa, lane[0], max(xb, xa + 1), lane[1]), fill=GUARDIAN)
        caption = [(f"guardian in control: {self.active_steps}/{self.n_steps} steps", BODY_OUTLINE)]
        self._row(img, self._row_h + self._u(1), caption, f"{self._span():.1f} s")
        self._label_rows = []
        groups = signal_groups(k for s in self.signals for k in s)
        # signals of the decision of step k (k >= 1) are drawn at the decision's time, the step's start
        if groups:
            top, lanes = lane[1] + self._u(3), list(groups.items())[:3]
            lane_h = (H - top) // len(lanes)
            for i, (name, keys) in enumerate(lanes):
                self._draw_lane(img, name, keys, top + i * lane_h, lane_h)
        self._strip, self._strip_key = img, key
        return img

    def _draw_lane(self, img: Image.Image, name: str, keys: list[str], y0: int, h: int) -> None:
        W = self.view.width
        d = ImageDraw.Draw(img)
        m = self._u(_MARGIN)
        series = {
            key: np.array([s.get(key, math.nan) for s in self.signals[1:]], dtype=float)
            for key in keys  # step k's signals (k >= 1)
        }
        t = np.array(self.times[:-1], dtype=float)
        finite = np.concatenate([v[np.isfinite(v)] for v in series.values()])
        d.line([(m, y0), (W - m, y0)], fill=LIGHT)
        label_h = round(1.4 * self.text_px)  # the labels' row, above the plot when the lane has room
        yb, yt = y0 + h - self._u(3), (y0 + label_h if h - label_h >= self.text_px else y0 + self._u(2))
        self._label_rows.append((y0 + 1, max(yt, y0 + label_h // 2) - 1))
        if finite.size == 0:
            self._row(img, y0 + self._u(2), [(f"{', '.join(keys)}: no value", BODY_OUTLINE)])
            return
        lo, hi = float(finite.min()), float(finite.max())
        if hi - lo < 1e-12:
            lo, hi = lo - 0.5, hi + 0.5
        pad = 0.08 * (hi - lo)
        lo, hi = lo - pad, hi + pad

        def y_of(v: np.ndarray) -> np.ndarray:
            return yb - (v - lo) / (hi - lo) * (yb - yt)

        if lo < 0 < hi:
            y = float(y_of(np.array([0.0]))[0])
            d.line([(m, y), (W - m, y)], fill=LIGHT)
        xs = m + (W - 2 * m) * np.clip(t / self._span(), 0.0, 1.0)
        lw = self._u(2)
        labels: list[tuple[str, tuple]] = []
        for j, (key, v) in enumerate(series.items()):
            colour = _THRESHOLD if "threshold" in key else _LINE_COLOURS[j % len(_LINE_COLOURS)]
            ys = y_of(v)
            ok = np.isfinite(ys)
            # a polyline per run of finite values; a lone value a dot
            start = None
            for i in range(len(ys) + 1):
                if i < len(ys) and ok[i]:
                    start = i if start is None else start
                    continue
                if start is not None:
                    pts = list(zip(xs[start:i].tolist(), ys[start:i].tolist(), strict=True))
                    if len(pts) > 1:
                        d.line(pts, fill=colour, width=lw if "threshold" not in key else max(1, lw // 2))
                    else:
                        r = max(1, lw // 2)
                        d.ellipse((pts[0][0] - r, pts[0][1] - r, pts[0][0] + r, pts[0][1] + r), fill=colour)
                    start = None
            labels += [(key, colour), ("   ", colour)]
        self._row(img, y0 + self._u(2), labels[:-1], f"[{lo + pad:.3g}, {hi - pad:.3g}]")
