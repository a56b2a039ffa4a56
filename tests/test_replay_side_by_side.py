"""``rmm-bench replay DIR --agent lrmm,cbf --episode E --video x.mp4|x.gif --frames F``: both agents'
episodes verified and written as one video, side by side on a shared simulated-time axis, read
back (frame count and size, two different panels, the rays the guardian sensed drawn, the shorter
episode's last frame held and marked); the results page links a pair's discordant episode to its
side-by-side replay."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rmm_bench.cli import main
from rmm_bench.sensed import HIT, RAY, RAY_FREE, text_size
from rmm_bench.side_by_side import ENDED, GAP, replay_anchor, shared_times, side_by_side_name

FAST = ["--workers", "1", "--no-progress", "--no-figure"]
SIZE, EVERY = 320, 4
HEADER = round(text_size(SIZE) * 1.7) + round(text_size(SIZE) * 1.7) % 2
STRIP = 132  # the strip under a 320-pixel view (rmm_envs.views.STRIP_HEIGHT at the smallest text)


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A fixed-clock run of Dubins4DParallel-v0 with lrmm and cbf, three short episodes each (0.4-s
    steps), and the first episode the two ran for different lengths (episode 2: lrmm collides)."""
    out = tmp_path_factory.mktemp("sbs") / "res"
    argv = ["--agent", "lrmm,cbf", "--clock", "fixed:1", "--episodes", "3", "--base-step", "0.4", "--out", str(out)]
    assert main([*argv, *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    rows = con.execute("SELECT agent, episode, steps, sim_time, outcome FROM episodes").fetchall()
    con.close()
    by = {(a, int(e)): (int(n), float(t), o) for a, e, n, t, o in rows}
    differ = [e for e in range(3) if by[("lrmm", e)][0] != by[("cbf", e)][0]]
    assert differ, "expected an episode that lrmm and cbf ran for different lengths"
    return out, differ[0], {a: by[(a, differ[0])] for a in ("lrmm", "cbf")}


def _mp4(path: Path) -> list[np.ndarray]:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    w, h = meta["size"]
    return [np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in reader]


def _gif(path: Path) -> list[np.ndarray]:
    out = []
    with Image.open(path) as im:
        for i in range(im.n_frames):
            im.seek(i)
            out.append(np.asarray(im.convert("RGB")))
    return out


def _near(a: np.ndarray, colour, tol: int) -> int:
    return int((np.abs(a.astype(int) - np.array(colour)).max(axis=-1) <= tol).sum())


def _views(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two panels' pictures (below the header, above the strip)."""
    view = frame[HEADER : HEADER + SIZE]
    return view[:, :SIZE], view[:, SIZE + GAP : 2 * SIZE + GAP]


def test_two_agents_side_by_side_are_verified_and_read_back_from_mp4_gif_and_pngs(run, tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    out, episode, rows = run
    n_lrmm, n_cbf = rows["lrmm"][0], rows["cbf"][0]
    short = 0 if n_lrmm < n_cbf else 1  # the panel whose episode ends first
    base = ["replay", str(out), "--agent", "lrmm,cbf", "--episode", str(episode), "--size", str(SIZE)]
    base += ["--every", str(EVERY)]
    assert main([*base, "--video", str(tmp_path / "x.mp4")]) == 0
    assert main([*base, "--video", str(tmp_path / "x.gif"), "--frames", str(tmp_path / "png")]) == 0
    text = capsys.readouterr().out
    assert (
        text.count(f"lrmm: episode {episode}: verified") == 2 and text.count(f"cbf: episode {episode}: verified") == 2
    )
    size = (2 * SIZE + GAP, HEADER + SIZE + STRIP)
    # one frame per shared time step (fixed clock: both step alike), every 8th and the last
    times = np.arange(max(n_lrmm, n_cbf) + 1)
    n = len(shared_times([times.tolist()], EVERY))
    assert f"wrote {tmp_path / 'x.mp4'} ({n} frames, {size[0]} x {size[1]}: lrmm, cbf side by side)" in text

    pngs = [np.asarray(Image.open(p).convert("RGB")) for p in sorted((tmp_path / "png").glob("frame_*.png"))]
    gif, mp4 = _gif(tmp_path / "x.gif"), _mp4(tmp_path / "x.mp4")
    for frames in (pngs, gif, mp4):
        assert len(frames) == n and frames[0].shape == (size[1], size[0], 3)

    for frames, tol in ((pngs, 0), (gif, 12), (mp4, 40)):
        mid = frames[len(frames) // 3]
        left, right = _views(mid)
        assert np.abs(left.astype(int) - right.astype(int)).max() > 100  # two different episodes drawn
        for panel in (left, right):  # the rays: lines to their hit points
            assert _near(panel, RAY, tol) + _near(panel, RAY_FREE, tol) > 150
        if tol == 0:
            assert _near(left, HIT, 0) + _near(right, HIT, 0) > 0

    # the shorter episode's last frame is held, dimmed and marked, while the other goes on
    last = max(n_lrmm, n_cbf)
    grid = list(range(0, last + 1, EVERY)) + ([last] if last % EVERY else [])  # the frames' step indices
    held = [f for f, g in zip(pngs, grid, strict=True) if g > min(n_lrmm, n_cbf)]
    assert len(held) >= 2
    panels = [_views(f)[short] for f in held]
    assert all(np.array_equal(p, panels[0]) for p in panels)
    goes_on = [_views(f)[1 - short] for f in held]
    assert not np.array_equal(goes_on[0], goes_on[-1])
    assert _near(panels[0], ENDED, 0) > 20  # the "ended: ..." mark
    assert _near(_views(pngs[0])[short], ENDED, 0) == 0
    for frames, tol in ((gif, 12), (mp4, 40)):
        a, b = _views(frames[-1])[short], _views(frames[-2])[short]
        assert np.abs(a.astype(int) - b.astype(int)).mean() < 2 and _near(a, ENDED, tol) > 20


def test_the_results_page_links_a_pairs_discordant_episode_to_its_side_by_side_replay(run, tmp_path):
    import shutil

    out, episode, rows = run
    copy = tmp_path / "res"
    shutil.copytree(out, copy)
    gif = copy / "replays" / side_by_side_name(("cbf", "lrmm"), episode)
    gif.parent.mkdir()
    argv = ["replay", str(copy), "--agent", "cbf,lrmm", "--episode", str(episode), "--size", "96", "--every", "50"]
    assert main([*argv, "--video", str(gif)]) == 0
    assert main(["report", str(copy), "--html"]) == 0
    page = (copy / "results.html").read_text()
    assert f"id='{replay_anchor(gif.name)}'" in page  # the replay embedded under its anchor
    assert "--agent cbf,lrmm --episode" in page  # the side-by-side command of a discordant episode
    con = sqlite3.connect(copy / "results.db")
    outcomes = dict(con.execute("SELECT agent, outcome FROM episodes WHERE episode = ?", (episode,)).fetchall())
    con.close()
    if outcomes["lrmm"] != outcomes["cbf"]:  # a discordant episode: the pair's details link to it
        assert f"href='#{replay_anchor(gif.name)}'" in page


def test_agents_that_did_not_start_alike_are_refused_in_one_line(tmp_path, capsys):
    from types import SimpleNamespace

    from rmm_bench.replay import _check_same_starts

    def target(env, seed, start):
        return SimpleNamespace(run=SimpleNamespace(env_id=env), row={"episode": 3, "seed": seed, "start": start})

    _check_same_starts(("a", "b"), [[target("E-v0", 1, "s")], [target("E-v0", 1, "s")]])
    for other in (target("F-v0", 1, "s"), target("E-v0", 2, "s"), target("E-v0", 1, "t")):
        with pytest.raises(ValueError, match="episode 3 of b did not start as a's did"):
            _check_same_starts(("a", "b"), [[target("E-v0", 1, "s")], [other]])


def test_a_side_by_side_name_is_a_plain_file_name():
    assert side_by_side_name(("lrmm", "cbf"), 6) == "lrmm-vs-cbf-episode-6.gif"
    assert side_by_side_name(("my/mod:Guard", "cbf"), 2, ".mp4") == "my_mod_Guard-vs-cbf-episode-2.mp4"
    assert replay_anchor("lrmm-vs-cbf-episode-6.gif") == "replay-lrmm-vs-cbf-episode-6"
