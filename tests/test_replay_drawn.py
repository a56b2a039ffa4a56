"""Replay draws a simulator of your own (its render() frames, render_mode passed by replay), and a
system that cannot draw is named as the cause in one line, never the guardian."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from rmm_bench.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"
if str(EXAMPLES) not in sys.path:  # own_simulator_wall: the tutorial's module, one copy for every test
    sys.path.insert(0, str(EXAMPLES))

NO_RENDER = """
import gymnasium as gym
from own_simulator_wall import CartWall, Driver, brake
from rmm_envs.envs.any_env import guarded


class Blind(CartWall):
    render = None  # no picture of a state


def make(clock=None, render_mode=None):
    d = Driver()
    return guarded(Blind(), driver=d, safe_default=brake, success=d.arrived, controls=("accel",),
                   max_episode_sim_time=10.0, clock=clock, render_mode=render_mode)


gym.register("BlindWall-v0", entry_point=make)
"""


@pytest.fixture
def research_dir(tmp_path, monkeypatch):
    (tmp_path / "blind_wall.py").write_text(NO_RENDER)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run(env: str, out: Path) -> None:
    assert main(["--agent", "brakes", "--env", env, "--episodes", "2", "--clock", "fixed:1", "--workers", "1",
                 "--no-progress", "--out", str(out)]) == 0  # fmt: skip


def test_replay_draws_a_simulator_of_your_own(research_dir, capsys):
    _run("own_simulator_wall:CartWall-v0", research_dir / "r")
    video = research_dir / "ep1.gif"
    argv = ["replay", "r", "--agent", "brakes", "--episode", "1", "--trust-modules", "--video", str(video)]
    assert main([*argv, "--size", "128"]) == 0
    assert "verified" in capsys.readouterr().out
    from PIL import Image

    with Image.open(video) as im:
        assert im.n_frames > 2 and im.size[0] == 128


def test_a_system_that_cannot_draw_is_named_as_the_cause(research_dir, capsys):
    _run("blind_wall:BlindWall-v0", research_dir / "r")
    capsys.readouterr()
    argv = ["replay", "r", "--agent", "brakes", "--episode", "0", "--trust-modules", "--video", "x.gif"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "BlindWall-v0 cannot draw its episodes" in err
    assert "render" in err and "guardian" not in err
    assert not (research_dir / "x.gif").exists()
    assert main(["replay", "r", "--agent", "brakes", "--episode", "0", "--trust-modules"]) == 0
