"""Writing a replayed episode's frames: a video (``.mp4`` through imageio-ffmpeg, ``.gif`` through
Pillow, chosen by the file's suffix) or one PNG per frame.

:func:`check_outputs` refuses, before anything is simulated, a suffix no writer supports, a
missing writer package and a folder that cannot be written; the writers write to a temporary
file beside the target and move it into place when the last frame is in, so an interrupted
replay never leaves half a video under the name asked for.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from rmm_bench.outputs import check_output, publish
from rmm_bench.sensed import draw_rays, ray_segments
from rmm_envs.views import EpisodeRecorder

__all__ = ["VIDEO_SUFFIXES", "EpisodeDrawing", "check_outputs", "episode_path", "write_frames", "write_video"]

#: suffix -> what writes it
VIDEO_SUFFIXES = {".mp4": "imageio-ffmpeg (pip install 'rmm-envs[video]')", ".gif": "Pillow"}


def _writable_folder(folder: Path, what: str) -> None:
    probe = folder
    while not probe.exists():  # the nearest existing parent must take new entries
        probe = probe.parent
    if not probe.is_dir() or not os.access(probe, os.W_OK | os.X_OK):
        raise ValueError(f"{what}: {probe} cannot be written; expected a folder this user may write to")


def check_outputs(video: Path | None, frames: Path | None, every: int, reads: Iterable[Path] = ()) -> None:
    """Refuse outputs that cannot be written, naming the value and what was expected (ValueError);
    ``reads``: the files the replay reads, which a video must never replace."""
    if every < 1:
        raise ValueError(f"--every must be an integer >= 1, got {every}")
    if video is not None:
        suffix = video.suffix.lower()
        if suffix not in VIDEO_SUFFIXES:
            raise ValueError(
                f"--video {video}: no writer for the suffix {suffix or '(none)'!r}; expected one of "
                f"{', '.join(VIDEO_SUFFIXES)}"
            )
        if suffix == ".mp4":
            try:
                import imageio_ffmpeg  # noqa: F401
            except ImportError:
                raise ValueError(
                    f"--video {video}: an .mp4 needs the package imageio-ffmpeg, which is not installed; "
                    "pip install 'rmm-envs[video]', or ask for a .gif"
                ) from None
        if video.is_dir():
            raise ValueError(f"--video {video}: it is a folder; expected a file name ending in .mp4 or .gif")
        check_output(video, "--video", reads)
        _writable_folder(video.resolve().parent, f"--video {video}")
    if frames is not None:
        if frames.exists() and not frames.is_dir():
            raise ValueError(f"--frames {frames}: it is a file; expected a folder for one PNG per frame")
        _writable_folder(frames.resolve(), f"--frames {frames}")


def episode_path(path: Path, episode: int, several: bool) -> Path:
    """The output of one episode: ``path`` itself for one episode, ``name-ep17.mp4`` (a file) or
    ``folder/ep17`` (a folder) when several episodes are replayed at once."""
    if not several:
        return path
    return path.with_name(f"{path.stem}-ep{episode}{path.suffix}") if path.suffix else path / f"ep{episode}"


def write_video(frames: Iterable[np.ndarray], path: Path, fps: float) -> int:
    """Write ``frames`` (each ``(H, W, 3)`` uint8, all one size) to ``path``; the number written."""
    path = Path(path)
    existed = path.exists()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)  # --video into a folder not made yet, as --frames does
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    except OSError as e:
        raise OSError(e.errno, e.strerror or str(e), str(path)) from None
    os.close(fd)
    tmp = Path(tmp_name)
    n = 0
    try:
        if path.suffix.lower() == ".mp4":
            import imageio_ffmpeg

            writer = None
            for frame in frames:
                if writer is None:
                    h, w = frame.shape[:2]
                    writer = imageio_ffmpeg.write_frames(
                        str(tmp), (w, h), fps=fps, codec="libx264", macro_block_size=2, quality=7
                    )
                    writer.send(None)  # start ffmpeg
                writer.send(np.ascontiguousarray(frame, dtype=np.uint8))
                n += 1
            if writer is not None:
                writer.close()
        else:
            images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
            n = len(images)
            if images:
                duration = max(20, int(round(1000.0 / fps / 10.0)) * 10)  # GIF delays are whole 10 ms
                images[0].save(tmp, save_all=True, append_images=images[1:], duration=duration, loop=0)
        if n == 0:
            raise ValueError(f"--video {path}: the episode has no frame to write")
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # a temporary file is private: the video gets the usual mode
        publish(tmp, path, existed)
    except OSError as e:  # name the video asked for, never the temporary file
        raise OSError(e.errno, e.strerror or str(e), str(path)) from None
    finally:
        tmp.unlink(missing_ok=True)
    return n


def write_frames(frames: Iterable[np.ndarray], folder: Path) -> int:
    """One PNG per frame in ``folder`` (``frame_00000.png``, ...); the number written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n = 0
    for n, frame in enumerate(frames, 1):
        tmp = folder / f".frame_{n - 1:05d}.png.tmp"
        Image.fromarray(np.asarray(frame, dtype=np.uint8)).save(tmp, format="PNG")
        os.replace(tmp, folder / f"frame_{n - 1:05d}.png")
    return n


class SharedSpanRecorder(EpisodeRecorder):
    """:class:`rmm_envs.views.EpisodeRecorder` whose strip may span a time set from outside
    (``span``: the longest episode of a side-by-side replay, so that the strips share one axis)."""

    span: float | None = None

    def _span(self) -> float:
        return self.span if self.span else super()._span()


class EpisodeDrawing:
    """The observer a replay passes to :func:`rmm_bench.runner.play_episode`: it records the
    episode with :class:`rmm_envs.views.EpisodeRecorder` (the guardian's ``signals()`` after every
    step) and the observations (``observe``: after the reset and after every step), then
    :meth:`frame` draws a frame with the rays the guardian sensed (:mod:`rmm_bench.sensed`) and
    :meth:`write` writes what was asked for."""

    def __init__(self, size: int = 512) -> None:
        self.size = int(size)
        self.recorder: EpisodeRecorder | None = None
        self.observations: list[np.ndarray | None] = []
        self.layout = None
        self.high: np.ndarray | None = None

    def begin(self, env) -> None:
        if self.recorder is None or self.recorder.env is not env:
            self.recorder = SharedSpanRecorder(env, size=self.size)
        self.recorder.begin()  # a new episode on the same env: the recorder starts afresh
        space = getattr(env, "observation_space", None)
        self.layout = getattr(space, "layout", None)
        high = getattr(space, "high", None)
        self.high = None if high is None else np.asarray(high, dtype=float)
        self.observations = []

    def observe(self, obs) -> None:
        """The observation the guardian is given next (after the reset, then after every step)."""
        try:
            self.observations.append(np.array(obs, dtype=float, copy=True))
        except (TypeError, ValueError):  # a dict or another structure: no rays to draw from it
            self.observations.append(None)

    def step(self, info, guardian) -> None:
        signals = guardian.signals() if hasattr(guardian, "signals") else {}
        assert self.recorder is not None  # begin() ran after the reset
        self.recorder.record(info, signals)

    @property
    def times(self) -> list[float]:
        """The simulated time of every frame (frame ``k`` ends step ``k``; frame 0 is the start)."""
        return [] if self.recorder is None else list(self.recorder.times)

    def frame(self, k: int) -> np.ndarray:
        """Frame ``k``: the recorder's, with the rays of the observation at ``k`` and the body over them."""
        rec = self.recorder
        assert rec is not None
        frame = rec.frame(k)
        obs = self.observations[k] if k < len(self.observations) else None
        segments = ray_segments(rec.view, rec.states[k], obs, self.layout, self.high)
        if not segments:
            return frame
        picture = Image.fromarray(frame)
        draw_rays(picture, segments, rec.view.width)
        if not rec.view.captures:  # the body over its rays
            rec.view.draw_body(ImageDraw.Draw(picture), rec.states[k], rec.active[k], rec.world)
        return np.asarray(picture)

    def frames(self, every: int = 1) -> Iterator[np.ndarray]:
        """Frames ``0, every, 2 every, ...`` and always the last one."""
        rec = self.recorder
        assert rec is not None
        last = rec.n_steps
        ks = list(range(0, last + 1, max(int(every), 1)))
        if ks[-1] != last:
            ks.append(last)
        for k in ks:
            yield self.frame(k)

    def write(self, video: Path | None, frames: Path | None, every: int, fps: float) -> list[str]:
        """Write the recorded episode; one line per output for the command to print."""
        rec = self.recorder
        if rec is None or rec.n_steps == 0:
            return []
        out = []
        if video is not None:
            n = write_video(self.frames(every=every), video, fps / every)
            out.append(f"wrote {video} ({n} frames, {rec.frame_size[1]} x {rec.frame_size[0]})")
        if frames is not None:
            n = write_frames(self.frames(every=every), frames)
            out.append(f"wrote {n} frames to {frames}")
        return out
