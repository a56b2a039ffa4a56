"""``rmm-bench check-system``: each check passes, is absent or fails for the reason it names; and a
simulator's own doomed-start test (its ``start_doomed`` hook) reaches Table I's columns."""

from __future__ import annotations

import sqlite3
import sys
from pathlib import Path

import pytest

from rmm_bench.cli import main

EXAMPLES = Path(__file__).resolve().parent.parent / "docs" / "examples"
if str(EXAMPLES) not in sys.path:  # own_simulator_wall: the tutorial's module, one copy for every test
    sys.path.insert(0, str(EXAMPLES))

VARIANTS = '''
import gymnasium as gym
import numpy as np
from own_simulator_wall import WALL, CartWall, Driver, brake
from rmm_envs.envs.any_env import guarded


class Shaky(CartWall):
    """Not deterministic: a push from the global RNG at every step."""

    def step(self, action):
        self.v += float(np.random.uniform(-0.01, 0.01))
        return super().step(action)


class Judged(CartWall):
    """Knows which starts are doomed: too fast to stop before the wall at full braking."""

    def start_doomed(self, state):
        x, v = float(state[0]), float(state[1])
        return bool(v > 0 and x + v * v / 2.0 >= WALL)

    def initial_state(self, rng):
        return np.array([rng.uniform(0.0, 1.8), rng.uniform(0.0, 2.5)])


def _make(cls):
    def make(clock=None, render_mode=None):
        d = Driver()
        return guarded(cls(), driver=d, safe_default=brake, success=d.arrived, controls=("accel",),
                       max_episode_sim_time=10.0, clock=clock, render_mode=render_mode)
    return make


gym.register("ShakyWall-v0", entry_point=_make(Shaky))
gym.register("JudgedWall-v0", entry_point=_make(Judged))
'''


@pytest.fixture(scope="module")
def _folder(tmp_path_factory):
    """One research folder for the module: its modules are imported once per process."""
    folder = tmp_path_factory.mktemp("research")
    (folder / "wall_variants.py").write_text(VARIANTS)
    return folder


@pytest.fixture
def research_dir(_folder, monkeypatch):
    monkeypatch.chdir(_folder)
    return _folder


def _lines(out: str) -> dict[str, str]:
    return {line[5:].split("  ")[0].strip(): line[:4].strip() for line in out.splitlines() if line[:4].strip()}


def test_the_tutorials_simulator_passes_and_the_estimate_is_printed(research_dir, capsys):
    assert (
        main(["check-system", "own_simulator_wall:CartWall-v0", "--configs", "64", "--samples-per-config", "64"]) == 0
    )
    out = capsys.readouterr().out
    status = _lines(out)
    assert status["env"] == status["contract"] == status["determinism"] == status["render"] == status["labels"] == "ok"
    assert status["doomed starts"] == "--"
    assert "labels/s per process" in out and "64 x 64 = 4096 labels" in out and "checks passed" in out


def test_a_simulator_that_is_not_deterministic_fails_the_check(research_dir, capsys):
    assert main(["check-system", "wall_variants:ShakyWall-v0", "--probe-states", "2"]) == 1
    out = capsys.readouterr().out
    assert _lines(out)["determinism"] == "FAIL" and "episodes from one seed differ" in out
    assert "failed: determinism" in out


def test_bad_input_is_one_line_and_exit_2(research_dir, capsys):
    assert main(["check-system", "NoSuchEnv-v0"]) == 2
    assert main(["check-system", "own_simulator_wall:CartWall-v0", "--configs", "0"]) == 2
    assert main(["check-system", "own_simulator_wall:CartWall-v0", "--env-opt", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "--configs must be an integer >= 1, got 0" in err[1] and "KEY=JSON" in err[2]


def test_a_simulators_start_doomed_hook_fills_the_doomed_columns(research_dir, capsys):
    assert main(["check-system", "wall_variants:JudgedWall-v0", "--probe-states", "2"]) == 0
    assert _lines(capsys.readouterr().out)["doomed starts"] == "ok"
    out = research_dir / "r"
    assert main(["--agent", "inactive", "--env", "wall_variants:JudgedWall-v0", "--episodes", "16",
                 "--clock", "fixed:1", "--workers", "1", "--no-progress", "--out", str(out)]) == 0  # fmt: skip
    with sqlite3.connect(out / "results.db") as con:
        rows = con.execute("SELECT doomed, method FROM starts").fetchall()
    assert len(rows) == 16 and {m for _, m in rows} == {"Judged.start_doomed"}
    assert {d for d, _ in rows} == {0, 1}  # both kinds of start, judged by the simulator
