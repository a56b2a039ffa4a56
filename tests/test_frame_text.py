"""The frames' own text stays legible when a video is small: read back from the frames, its height
grows with the panel and is at least 10 pixels for capitals at 320, the status line is drawn under
the scene (or only in its corner when there is no strip), the texts of a row never run into one
another, and the side-by-side headers keep an agent's name clear of the time; the docs' GIFs are
what their command draws today."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image, ImageDraw

from rmm_bench.cli import main
from rmm_bench.side_by_side import ENDED, GAP, side_by_side_frames
from rmm_bench.video import EpisodeDrawing, SharedSpanRecorder
from rmm_envs.views import EpisodeRecorder, View
from rmm_envs.views.base import OBSTACLE
from rmm_envs.views.text import text_size

SIZES = (320, 512, 1024)


class _Plain(View):
    """A view of one colour (no scene to tell apart from the text), ``size`` pixels square."""

    def __init__(self, size: int, colour=(255, 255, 255)) -> None:
        self.width = self.height = int(size)
        self.colour = colour

    def draw_static(self, draw: ImageDraw.ImageDraw, world) -> None:
        draw.rectangle((0, 0, self.width, self.height), fill=self.colour)

    def state(self, env) -> np.ndarray:
        return np.zeros(3)


def _recorded(rec: EpisodeRecorder, steps: int = 20, key: str = "HIT", outcome: str | None = None):
    """``rec`` after a hand-made episode: the guardian in control for steps 5-9, one signal ``key``."""
    rec.begin()
    for k in range(1, steps + 1):
        rec.add(np.zeros(3), 5 <= k < 10, 0.1 * k, {key: float(k % 7)}, outcome if k == steps else None)
    return rec


def _ink(a: np.ndarray, dark: int = 150) -> np.ndarray:
    """Pixels of text (every channel below ``dark``: black, the signal's grey, the driver's blue)."""
    return np.asarray((a.astype(int) < dark).all(axis=-1))


def _rows(mask: np.ndarray) -> tuple[int, int]:
    r = np.flatnonzero(mask.any(axis=1))
    return int(r[0]), int(r[-1])


def _runs(cols: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a 1-D array, ``(first, last)``."""
    out, start = [], None
    for i, c in enumerate([*cols.tolist(), False]):
        if c and start is None:
            start = i
        elif not c and start is not None:
            out.append((start, i - 1))
            start = None
    return out


def _label_cap_height(size: int) -> int:
    """The height of the signal lane's label ``HIT`` (capitals only) in a frame ``size`` wide."""
    rec = _recorded(EpisodeRecorder(None, _Plain(size)))
    frame = rec.frame(0)
    strip = frame[rec.view.height :]
    top = rec.lane_rows[1] + 2  # the signal lane: its label at the top left, its range at the right
    label = _ink(strip[top : top + round(1.4 * rec.text_px), rec._u(6) + 2 : size // 3], dark=110)
    a, b = _rows(label)
    return b - a + 1


def test_capitals_are_at_least_ten_pixels_at_320_and_grow_with_the_frame():
    heights = {s: _label_cap_height(s) for s in SIZES}
    assert heights[320] >= 10, heights
    assert heights[512] >= 13 and heights[1024] >= 25, heights
    assert heights[320] < heights[512] < heights[1024]
    # the text is drawn at text_size of the panel: the measured capitals follow it
    for s in SIZES:
        assert 0.6 * text_size(s) <= heights[s] <= 0.8 * text_size(s), (s, heights[s], text_size(s))


@pytest.mark.parametrize("size", SIZES)
def test_the_status_line_is_legible_and_leaves_the_scene_alone(size):
    rec = _recorded(EpisodeRecorder(None, _Plain(size, OBSTACLE)), outcome="goal")
    s = rec.text_px
    for frame in (rec.frame(7), rec.frame()):
        view = frame[:size].astype(int)
        assert (view == np.array(OBSTACLE)).all()  # the scene: not a pixel of text over it
        top, bottom = rec.status_rows
        assert top == size and bottom - top <= 1.6 * s
        a, b = _rows(_ink(frame[top:bottom]))
        assert b - a + 1 >= 0.8 * s >= 11  # the line's letters, ascenders to descenders
        # the caption under it starts below its last row of ink
        caption = _ink(frame[bottom : size + rec.lane_rows[0]])
        assert _rows(caption)[0] + bottom > b + top


@pytest.mark.parametrize("size", SIZES)
def test_without_a_strip_the_status_line_covers_only_its_corner(size):
    rec = _recorded(EpisodeRecorder(None, _Plain(size, OBSTACLE), strip_height=0), outcome="goal")
    s = rec.text_px
    frame = rec.frame()
    assert frame.shape[0] == size
    changed = np.abs(frame.astype(int) - np.array(OBSTACLE)).max(axis=-1) > 0
    top, bottom = _rows(changed)
    cols = np.flatnonzero(changed.any(axis=0))
    assert bottom < size and size - top <= 2.2 * s and bottom - top + 1 <= 1.6 * s
    assert cols[0] <= rec._u(10) and cols[-1] < 0.95 * size
    assert changed.sum() <= 0.08 * size * size
    a, b = _rows(_ink(frame[top : bottom + 1]))  # dark text on its pale backing, over the red scene
    assert b - a + 1 >= 0.8 * s


@pytest.mark.parametrize("size", (160, 320, 512))
def test_the_strips_texts_never_run_into_one_another(size):
    rec = _recorded(EpisodeRecorder(None, _Plain(size)), steps=400, key="risk_threshold_of_a_long_name")
    frame = rec.frame(0)  # the cursor at the strip's left margin, left of every text
    strip = frame[rec.view.height :]
    lane, (status, caption) = rec.lane_rows, rec.status_rows
    m = rec._u(6)
    y0 = lane[1] + rec._u(3)  # the signal's lane: its label's row, then its plot
    rows = ((caption - status, lane[0]), (y0 + 1, y0 + round(1.4 * rec.text_px) - 1))
    for top, bottom in rows:  # the lane's caption, the signal's label
        row = _ink(strip[top:bottom, m + 2 :], dark=200)
        runs = _runs(row.any(axis=0))
        assert runs, (top, bottom)
        assert runs[-1][1] + m + 2 < size  # inside the frame
        gaps = [b[0] - a[1] - 1 for a, b in zip(runs, runs[1:], strict=False)]
        if size >= 320:  # both texts at full size, apart: the widest gap is the one between them
            assert max(gaps) >= rec.text_px, (size, top, gaps)
    # the time cursor crosses no text: from the left margin to the right one, the rows of text
    # (but the status line's, which changes) are the same in every frame
    last = rec.frame()[rec.view.height :]
    assert not np.array_equal(last[lane[0] :], strip[lane[0] :])  # the cursor moved
    for top, bottom in rows:
        assert np.array_equal(last[top:bottom], strip[top:bottom]), (size, top)


def test_a_side_by_side_header_keeps_a_long_name_clear_of_the_time_and_the_labels_legible():
    size = 320
    drawings = []
    for steps in (30, 20):
        d = EpisodeDrawing(size)
        d.recorder = _recorded(SharedSpanRecorder(None, _Plain(size)), steps=steps, outcome="collision")
        drawings.append(d)
    names = ["my_guardians.package.module:AVeryLongGuardianClassName", "cbf"]
    frames = list(side_by_side_frames(names, drawings))
    header = round(text_size(size) * 1.7)
    header += header % 2
    frame = frames[-1]
    assert frame.shape[1] == 2 * size + GAP
    for x0 in (0, size + GAP):
        band = _ink(frame[:header, x0 : x0 + size], dark=120)
        runs = _runs(band.any(axis=0))
        gaps = [b[0] - a[1] - 1 for a, b in zip(runs, runs[1:], strict=False)]
        widest = max(gaps)
        assert widest >= text_size(size) // 2  # the name, then a clear gap, then the time
        assert runs[-1][1] < size - 2 and runs[0][0] > 0
        a, b = _rows(band)
        assert b - a + 1 >= 10  # the header's letters: at least their capitals' height
    # the shorter episode's panel is held and marked over its status line, under the scene
    right = frame[header:, size + GAP :]
    mark = np.abs(right.astype(int) - np.array(ENDED)).max(axis=-1) <= 10
    rows = np.flatnonzero(mark.any(axis=1))
    top, bottom = drawings[1].recorder.status_rows
    assert rows.size and top - 6 <= rows[0] < rows[-1] <= bottom + 6
    assert not mark[: top - 6].any()


@pytest.mark.heavy
def test_the_docs_gifs_are_verified_replays_drawn_by_the_recorder_as_it_is(tmp_path, capsys):
    """``docs/figures/watch_AGENT_ep2.gif`` (the README's picture among them) is what the command
    beside it in docs/watching.md and the README makes now, frame for frame: a replay verified
    against its stored row, drawn by today's recorder (rays, text).  A change to the drawing fails
    here until the figures are made again with that command."""
    figures = Path(__file__).resolve().parents[1] / "docs" / "figures"
    out = tmp_path / "results-watch"  # the docs' run has 8 episodes; episode 2 is the same in 3
    run = ["--agent", "inactive,lrmm,cbf", "--episodes", "3", "--clock", "fixed:1", "--out", str(out)]
    assert main([*run, "--workers", "1", "--no-progress", "--no-figure"]) == 0
    for agent in ("inactive", "lrmm", "cbf"):
        gif = tmp_path / f"{agent}-ep2.gif"
        argv = ["replay", str(out), "--agent", agent, "--episode", "2", "--video", str(gif), "--size", "320"]
        assert main([*argv, "--every", "4", "--no-progress"]) == 0
        assert "episode 2: verified" in capsys.readouterr().out
        with Image.open(gif) as made, Image.open(figures / f"watch_{agent}_ep2.gif") as shipped:
            assert (made.n_frames, made.size) == (shipped.n_frames, shipped.size), agent
            for i in range(made.n_frames):
                made.seek(i)
                shipped.seek(i)
                a, b = np.asarray(made.convert("RGB"), int), np.asarray(shipped.convert("RGB"), int)
                # the same picture (a FreeType of another version may shade a letter's edge otherwise)
                assert (np.abs(a - b).max(axis=-1) > 40).mean() < 0.002, (agent, i)
