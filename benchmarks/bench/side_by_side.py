"""Several agents' replays of one episode side by side, on a shared simulated-time axis.

``rmm-bench replay DIR --agent lrmm,cbf --episode 6 --video x.mp4``: each agent's episode is
re-simulated and verified, recorded by its own :class:`rmm_bench.video.EpisodeDrawing`, and
:func:`side_by_side_frames` composes one frame per simulated time at which any of them took a
step: each agent's panel shows its last frame at or before that time, under a header naming the
agent and the shared time.  An agent whose episode ended holds its last frame, dimmed, marked
``ended: collision at 7.3 s``.  The strips under the panels span the longest episode, so the
guardians' intervals line up.  Text and lines scale with the panel's width
(:mod:`rmm_bench.sensed`), legible at 320 pixels.

:func:`side_by_side_name` is the file name under ``DIR/replays/`` that the results page links to
a pair's discordant episode.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence

import numpy as np
from PIL import Image, ImageDraw

from rmm_bench.sensed import font, text_size

__all__ = [
    "ENDED",
    "GAP",
    "REPLAYS",
    "frame_size",
    "replay_anchor",
    "shared_times",
    "side_by_side_frames",
    "side_by_side_name",
]

#: the folder of a results directory that holds its replays (``AGENT-episode-N.gif``, and
#: :func:`side_by_side_name`'s ``A-vs-B-episode-N.gif``), which the results page shows and links to
REPLAYS = "replays"
#: pixels between two panels
GAP = 8
_GAP_COLOUR = (60, 60, 60)
_HEADER = (245, 245, 247)
_TEXT = (20, 20, 20)
#: the mark of an episode that ended (its last frame held)
ENDED = (150, 20, 20)


def side_by_side_name(agents: Sequence[str], episode: int, suffix: str = ".gif") -> str:
    """``lrmm-vs-cbf-episode-6.gif``: the agents in the order given (characters other than letters,
    digits, ``.``, ``_`` and ``-`` replaced by ``_``)."""
    safe = [re.sub(r"[^A-Za-z0-9._-]", "_", a) for a in agents]
    return f"{'-vs-'.join(safe)}-episode-{int(episode)}{suffix}"


def replay_anchor(name: str) -> str:
    """The results page's anchor of the replay file ``name`` (``replay-lrmm-vs-cbf-episode-6``)."""
    stem = name.rsplit(".", 1)[0] if "." in name else name
    return "replay-" + re.sub(r"[^A-Za-z0-9_-]", "_", stem)


def shared_times(times: Sequence[Sequence[float]], every: int = 1) -> list[float]:
    """Every simulated time at which one of the episodes has a frame, in order (every ``every``-th,
    and always the last)."""
    grid = sorted({round(float(t), 9) for ts in times for t in ts})
    if not grid:
        return []
    kept = grid[:: max(int(every), 1)]
    if kept[-1] != grid[-1]:
        kept.append(grid[-1])
    return kept


def _frame_at(times: Sequence[float], t: float) -> int:
    """The last frame at or before ``t`` (frame 0 before the first step)."""
    k = int(np.searchsorted(np.round(np.asarray(times, dtype=float), 9), round(t, 9), side="right")) - 1
    return max(k, 0)


def _even(n: int) -> int:
    return n + (n % 2)


class _Panel:
    """One agent's column: its drawing, the last frame composed (held while it does not change)."""

    def __init__(self, agent: str, drawing) -> None:
        self.agent = agent
        self.drawing = drawing
        self.times = drawing.times
        self.k = -1
        self.picture: np.ndarray | None = None

    def at(self, t: float) -> tuple[np.ndarray, bool]:
        k = _frame_at(self.times, t)
        if k != self.k or self.picture is None:
            self.k, self.picture = k, self.drawing.frame(k)
        return self.picture, t > self.times[-1] + 1e-9


def _ended_text(drawing) -> str:
    outcome = drawing.recorder.outcome
    end = drawing.times[-1]
    return f"ended: {outcome} at {end:.1f} s" if outcome else f"ended at {end:.1f} s"


def _compose(panels: list[_Panel], t: float, header: int, size: int):
    width = sum(p.drawing.recorder.frame_size[1] for p in panels) + GAP * (len(panels) - 1)
    height = header + max(p.drawing.recorder.frame_size[0] for p in panels)
    out = Image.new("RGB", (_even(width), _even(height)), _GAP_COLOUR)
    text = font(size)
    small = font(max(11, round(size * 0.85)))
    x = 0
    for p in panels:
        frame, ended = p.at(t)
        h, w = frame.shape[:2]
        picture = Image.fromarray(frame)
        status = p.drawing.recorder.status_rows
        d = ImageDraw.Draw(picture)
        if ended:  # held: dimmed, marked over the recorder's status line
            picture = Image.blend(picture, Image.new("RGB", picture.size, (255, 255, 255)), 0.35)
            d = ImageDraw.Draw(picture)
            label = _ended_text(p.drawing)
            box = d.textbbox((0, 0), label, font=text)
            pad = max(4, size // 3)
            bh = box[3] - box[1] + 2 * pad
            top = (status[0] + status[1] - bh) // 2
            d.rectangle((0, top, w, top + bh), fill=(255, 255, 255), outline=ENDED, width=2)
            d.text(((w - (box[2] - box[0])) / 2 - box[0], top + pad - box[1]), label, fill=ENDED, font=text)
        band = Image.new("RGB", (w, header), _HEADER)
        bd = ImageDraw.Draw(band)
        pad = (header - size) // 2
        stamp = f"t = {t:.2f} s"
        room = w - 3 * pad - bd.textlength(stamp, font=small)  # the name never runs into the time
        name = p.agent
        while len(name) > 2 and bd.textlength(name, font=text) > room:  # a long module:Class
            name = name[:-2] + "…"
        bd.text((pad, pad), name, fill=_TEXT, font=text)
        lift = (size - int(getattr(small, "size", size))) // 2
        bd.text((w - pad - bd.textlength(stamp, font=small), pad + lift), stamp, fill=_TEXT, font=small)
        out.paste(band, (x, 0))
        out.paste(picture, (x, header))
        x += w + GAP
    return np.asarray(out)


def side_by_side_frames(agents: Sequence[str], drawings: Sequence, every: int = 1) -> Iterator[np.ndarray]:
    """The side-by-side frames of ``drawings`` (one per agent, each holding one recorded episode),
    one per shared simulated time (:func:`shared_times`)."""
    span = max(d.times[-1] for d in drawings)
    for d in drawings:  # one time axis for every strip
        d.recorder.span = span if span > 0 else None
    panels = [_Panel(a, d) for a, d in zip(agents, drawings, strict=True)]
    size = text_size(min(d.recorder.frame_size[1] for d in drawings))
    header = _even(round(size * 1.7))
    for t in shared_times([d.times for d in drawings], every):
        yield _compose(panels, t, header, size)


def frame_size(drawings: Sequence) -> tuple[int, int]:
    """``(height, width)`` of the side-by-side frames of ``drawings``."""
    size = text_size(min(d.recorder.frame_size[1] for d in drawings))
    width = sum(d.recorder.frame_size[1] for d in drawings) + GAP * (len(drawings) - 1)
    height = _even(round(size * 1.7)) + max(d.recorder.frame_size[0] for d in drawings)
    return _even(height), _even(width)
