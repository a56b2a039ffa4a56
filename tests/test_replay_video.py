"""``rmm-bench replay --video/--frames/--every``: the replayed episode's frames written as an MP4, a
GIF or PNGs, read back (frame count and size), the intervention strip matching the stored row,
and every bad output refused in one line before anything is simulated or written."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from rmm_bench.cli import main
from rmm_bench.video import episode_path, write_video

FAST = ["--workers", "1", "--no-progress", "--no-figure"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A fixed-clock run of Dubins4DParallel-v0 with lrmm and cbf, two episodes each."""
    out = tmp_path_factory.mktemp("video") / "res"
    argv = ["--agent", "lrmm,cbf", "--clock", "fixed:1", "--episodes", "2", "--out", str(out)]
    assert main([*argv, *FAST]) == 0
    return out


def _rows(out: Path, agent: str) -> dict[int, dict]:
    con = sqlite3.connect(out / "results.db")
    con.row_factory = sqlite3.Row
    rows = con.execute("SELECT * FROM episodes WHERE agent = ?", (agent,)).fetchall()
    con.close()
    return {int(r["episode"]): dict(r) for r in rows}


def _mp4_frames(path: Path) -> tuple[int, tuple[int, int]]:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    meta = reader.__next__()
    n = sum(1 for _ in reader)
    return n, tuple(meta["size"])


def test_an_mp4_a_gif_and_pngs_hold_every_kth_frame_of_the_episode(run, tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    steps = {i: int(r["steps"]) for i, r in _rows(run, "lrmm").items()}
    assert main(["replay", str(run), "--agent", "lrmm", "--episode", "0", "--video", str(tmp_path / "a.mp4")]) == 0
    out = capsys.readouterr().out
    size = (512, 512 + 170)  # the view, then the strip, 170 pixels at 512 (it grows with the text)
    assert "episode 0: verified" in out and f"wrote {tmp_path / 'a.mp4'} ({steps[0] + 1} frames, 512 x 682)" in out
    assert _mp4_frames(tmp_path / "a.mp4") == (steps[0] + 1, size)  # the start and one frame per step
    every = 4
    assert (
        main(["replay", str(run), "--agent", "cbf", "--episode", "0,1", "--video", str(tmp_path / "c.gif")]
             + ["--frames", str(tmp_path / "png"), "--every", str(every), "--no-progress"])
        == 0
    )  # fmt: skip
    cbf_steps = {i: int(r["steps"]) for i, r in _rows(run, "cbf").items()}
    for i in (0, 1):
        expected = len(range(0, cbf_steps[i] + 1, every)) + (cbf_steps[i] % every != 0)  # and always the last
        gif = Image.open(tmp_path / f"c-ep{i}.gif")
        assert (gif.n_frames, gif.size) == (expected, size)
        pngs = sorted((tmp_path / "png" / f"ep{i}").glob("frame_*.png"))
        assert len(pngs) == expected and Image.open(pngs[-1]).size == size
    assert not list(tmp_path.glob(".*"))  # no temporary file left


def test_the_intervention_strip_matches_the_stored_active_steps(run):
    from rmm_bench.replay import ReplayRequest, build_env, plan_replay, replay_episode
    from rmm_bench.store import ResultsStore
    from rmm_bench.video import EpisodeDrawing

    for agent in ("lrmm", "cbf"):
        store = ResultsStore(run / "results.db", read_only=True)
        req = ReplayRequest(dir=run, agent=agent, episodes=(0, 1), where=None, limit=None, allow_errors=False,
                            trust_modules=False, env=None, invocation=None, progress=False)  # fmt: skip
        targets = plan_replay(store, req)
        store.close()
        env = build_env(targets[0])
        for target in targets:
            drawing = EpisodeDrawing(size=128)
            message, ok = replay_episode(target, env, drawing)
            assert ok, message
            rec = drawing.recorder
            assert rec.n_steps == target.row["steps"]
            assert rec.active_steps == target.row["active_steps"]
            frame = rec.frame()
            assert frame.shape == (128 + rec.strip_height, 128, 3) and frame.dtype == np.uint8
        env.close()


@pytest.mark.parametrize(
    ("option", "value", "says"),
    [
        ("--video", "x.avi", "--video {v}: no writer for the suffix '.avi'; expected one of .mp4, .gif"),
        ("--video", "x", "--video {v}: no writer for the suffix '(none)'; expected one of .mp4, .gif"),
        (
            "--video",
            "afile/x.gif",
            "--video {v}: {tmp}/afile cannot be written; expected a folder this user may write to",
        ),
        ("--frames", "afile", "--frames {v}: it is a file; expected a folder for one PNG per frame"),
        ("--every", "0", "--every must be an integer >= 1, got 0"),
    ],
)
def test_a_bad_output_is_refused_in_one_line_before_anything_runs(run, tmp_path, capsys, monkeypatch, option, value,
                                                                   says):  # fmt: skip
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("")
    before = sorted(p.name for p in tmp_path.iterdir())
    capsys.readouterr()
    assert main(["replay", str(run), "--agent", "lrmm", "--episode", "0", option, value, "--no-progress"]) == 2
    cap = capsys.readouterr()
    assert cap.err.strip() == f"rmm-bench: error: {says.format(v=value, tmp=tmp_path)}" and "verified" not in cap.out
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_outputs_of_several_episodes_are_named_by_episode_and_an_empty_video_is_refused(tmp_path):
    assert episode_path(Path("v/a.mp4"), 17, several=True) == Path("v/a-ep17.mp4")
    assert episode_path(Path("v/a.mp4"), 17, several=False) == Path("v/a.mp4")
    assert episode_path(Path("frames"), 3, several=True) == Path("frames/ep3")
    with pytest.raises(ValueError, match="the episode has no frame to write"):
        write_video(iter(()), tmp_path / "empty.gif", 10.0)
    assert list(tmp_path.iterdir()) == []  # the temporary file is gone too


@pytest.mark.parametrize(
    ("env_id", "agent"),
    [
        ("Dubins3DMazeParallel-v0", "lrmm"),
        ("Dubins4DMapParallel-v0", "lrmm"),
        ("QuadrotorRoomParallel-v0", "cbf"),
        ("CartPoleParallel-v0", "lrmm"),
        ("InvertedPendulumParallel-v0", "lrmm"),
    ],
)
def test_every_system_writes_an_mp4_and_a_gif_that_read_back_with_its_strip_matching_the_row(
    env_id, agent, tmp_path, capsys
):
    """Each guardian env of the system table (Dubins4D above): one stored episode, replayed to an
    MP4 and a GIF, both read back (frame count and size as the command printed them), and the
    recorder's intervention strip holding the stored ``active_steps``."""
    pytest.importorskip("imageio_ffmpeg")
    if env_id.startswith("InvertedPendulum"):
        pytest.importorskip("mujoco")
    from rmm_bench.replay import ReplayRequest, build_env, plan_replay, replay_episode
    from rmm_bench.store import ResultsStore
    from rmm_bench.video import EpisodeDrawing

    out = tmp_path / "res"
    argv = ["--agent", agent, "--env", env_id, "--clock", "fixed:1", "--episodes", "1", "--out", str(out)]
    assert main([*argv, *FAST]) == 0
    capsys.readouterr()
    row = _rows(out, agent)[0]
    steps = int(row["steps"])
    replay = ["replay", str(out), "--agent", agent, "--episode", "0", "--size", "160", "--no-progress"]
    assert main([*replay, "--video", str(tmp_path / "a.mp4")]) == 0
    wrote = capsys.readouterr().out.splitlines()
    assert wrote[0] == "episode 0: verified"
    n, size = _mp4_frames(tmp_path / "a.mp4")
    assert wrote[1] == f"wrote {tmp_path / 'a.mp4'} ({steps + 1} frames, {size[0]} x {size[1]})" and n == steps + 1
    assert main([*replay, "--video", str(tmp_path / "a.gif"), "--every", "10"]) == 0
    gif = Image.open(tmp_path / "a.gif")
    assert gif.n_frames == len(range(0, steps + 1, 10)) + (steps % 10 != 0) and gif.size == size

    store = ResultsStore(out / "results.db", read_only=True)
    req = ReplayRequest(dir=out, agent=agent, episodes=(0,), where=None, limit=None, allow_errors=False,
                        trust_modules=False, env=None, invocation=None, progress=False)  # fmt: skip
    (target,) = plan_replay(store, req)
    store.close()
    env = build_env(target)
    drawing = EpisodeDrawing(size=96)
    message, ok = replay_episode(target, env, drawing)
    env.close()
    assert ok, message
    rec = drawing.recorder
    assert (rec.n_steps, rec.active_steps) == (steps, row["active_steps"])
    assert int(np.count_nonzero(rec.active[1:])) == row["active_steps"]  # the strip's intervals are these steps
