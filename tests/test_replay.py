"""``rmm-bench replay`` (benchmarks/bench/replay.py): stored episodes re-simulate exactly and are
verified against their rows, fixed clock and wall clock (from the stored clock trace) alike; a
difference is named and exits 1; every bad input is one line and exit 2; the database is never
written."""

from __future__ import annotations

import hashlib
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from rmm_bench import runner
from rmm_bench.cli import main
from rmm_bench.store import SCHEMA_VERSION
from rmm_envs.clocks import ReplayClock, TraceExhausted

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).parent / "data"
FAST = ["--workers", "1", "--no-progress", "--no-figure"]


def _run(out: Path, agents: str, clock: str, episodes: int = 3, env: str = "Dubins4DParallel-v0", *extra) -> None:
    argv = ["--agent", agents, "--env", env, "--clock", clock, "--episodes", str(episodes), "--out", str(out)]
    assert main([*argv, *FAST, *extra]) == 0


def _replay(capsys, *argv) -> tuple[int, str, str]:
    capsys.readouterr()
    code = main(["replay", *map(str, argv), "--no-progress"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Fixed-clock and wall-clock runs of Dubins4DParallel-v0 (lrmm, cbf) and CartPoleParallel-v0 (lrmm)."""
    base = tmp_path_factory.mktemp("replay")
    _run(base / "fixed", "lrmm,cbf", "fixed:2")
    _run(base / "wall", "lrmm,cbf", "wall")
    _run(base / "cartpole", "lrmm", "wall", 3, "CartPoleParallel-v0")
    return base


@pytest.mark.parametrize(("name", "agent"), [("fixed", "lrmm"), ("fixed", "cbf"), ("wall", "lrmm"), ("wall", "cbf")])
def test_every_stored_episode_is_verified(runs, capsys, name, agent):
    db = runs / name / "results.db"
    before = _digest(db)
    code, out, err = _replay(capsys, runs / name, "--agent", agent, "--episode", "0,1,2")
    assert code == 0, err
    assert [line for line in out.splitlines() if line.startswith("episode")] == [
        f"episode {i}: verified" for i in range(3)
    ]
    assert _digest(db) == before  # opened read-only


def test_wall_clock_runs_store_their_traces_and_fixed_ones_none(runs):
    con = sqlite3.connect(runs / "wall" / "results.db")
    assert con.execute("SELECT COUNT(*) FROM clock_traces").fetchone()[0] == 6
    steps = dict(con.execute("SELECT run_key || episode, steps FROM episodes").fetchall())
    laps = dict(con.execute("SELECT run_key || episode, n FROM clock_traces").fetchall())
    assert laps == steps  # one lap per step
    con.close()
    con = sqlite3.connect(runs / "fixed" / "results.db")
    assert con.execute("SELECT COUNT(*) FROM clock_traces").fetchone()[0] == 0
    con.close()


def test_cartpole_wall_clock_is_verified_with_where_and_limit(runs, capsys):
    code, out, _ = _replay(capsys, runs / "cartpole", "--agent", "lrmm", "--where", "steps > 0", "--limit", "2")
    assert code == 0
    assert out.splitlines()[:2] == ["episode 0: verified", "episode 1: verified"]
    assert "verified: 2 episodes of lrmm" in out


def test_a_fresh_process_verifies_a_wall_clock_episode(runs):
    """What a user runs: a new process (its own warm-up) replays the stored episode."""
    proc = subprocess.run(
        [sys.executable, "-m", "rmm_bench.cli", "replay", str(runs / "wall"), "--agent", "lrmm", "--episode", "1"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "episode 1: verified"


def test_a_hand_edited_outcome_is_the_differing_column(runs, tmp_path, capsys):
    shutil.copytree(runs / "wall", tmp_path / "edited")
    con = sqlite3.connect(tmp_path / "edited" / "results.db")
    stored = con.execute("SELECT outcome FROM episodes WHERE agent = 'cbf' AND episode = 1").fetchone()[0]
    other = "collision" if stored != "collision" else "goal"
    con.execute("UPDATE episodes SET outcome = ? WHERE agent = 'cbf' AND episode = 1", (other,))
    con.commit()
    con.close()
    code, out, _ = _replay(capsys, tmp_path / "edited", "--agent", "cbf", "--episode", "0,1")
    assert code == 1
    lines = out.splitlines()
    assert lines[0] == "episode 0: verified"
    assert lines[1].startswith(f"episode 1: differs in outcome: stored {other!r}, replayed {stored!r}")


def test_an_edited_guardian_stat_is_named_and_timing_stats_are_not_compared(runs, tmp_path, capsys):
    shutil.copytree(runs / "fixed", tmp_path / "edited")
    con = sqlite3.connect(tmp_path / "edited" / "results.db")
    con.execute(
        "UPDATE episodes SET wall_time = 1e9, decision_max = 5.0, guardian_stats = "
        "json_set(guardian_stats, '$.solve_seconds', 12.5) WHERE agent = 'cbf' AND episode = 0"
    )
    con.execute(
        "UPDATE episodes SET guardian_stats = json_set(guardian_stats, '$.qp_fallbacks', 999) "
        "WHERE agent = 'cbf' AND episode = 2"
    )
    con.commit()
    con.close()
    code, out, _ = _replay(capsys, tmp_path / "edited", "--agent", "cbf", "--episode", "0,2")
    assert code == 1
    assert out.splitlines()[0] == "episode 0: verified"  # timings differ, results do not
    assert "episode 2: differs in " in out.splitlines()[1] and "replayed" in out.splitlines()[1]
    assert runner.is_timing_stat("solve_seconds") and not runner.is_timing_stat("qp_fallbacks")


def test_a_wrong_trace_is_a_difference_not_a_verification(runs, tmp_path, capsys):
    shutil.copytree(runs / "wall", tmp_path / "edited")
    con = sqlite3.connect(tmp_path / "edited" / "results.db")
    key = con.execute("SELECT run_key FROM runs WHERE agent = 'lrmm'").fetchone()[0]
    from rmm_bench.store import encode_laps

    con.execute(
        "UPDATE clock_traces SET n = 3, laps = ? WHERE run_key = ? AND episode = 0", (encode_laps([0.5] * 3), key)
    )
    con.commit()
    con.close()
    code, out, _ = _replay(capsys, tmp_path / "edited", "--agent", "lrmm", "--episode", "0")
    assert code == 1
    assert "differs" in out and "ran out" in out and f"episode 0 of lrmm's run {key}" in out
    assert "cannot be verified" in out


def test_replay_clock_plays_back_and_refuses_past_its_end():
    clock = ReplayClock([0.25, 1e-7], "episode 4 of run x")
    clock.start()
    assert (clock.elapsed(), clock.elapsed()) == (0.25, 1e-7)
    with pytest.raises(TraceExhausted, match="episode 4 of run x.*holds 2 laps"):
        clock.elapsed()


def test_errored_episode_replays_only_with_allow_errors(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "boom"
    argv = ["--agent", "tests.bench_helpers:Boom", "--clock", "fixed:1", "--episodes", "2", "--out", str(out), *FAST]
    assert main(argv) == 1  # a guardian error is a result: exit 1
    code, _, err = _replay(capsys, out, "--agent", "tests.bench_helpers:Boom", "--episode", "0")
    assert code == 2 and "--episode 0: it ended in an error of kind guardian" in err and "--allow-errors" in err
    code, text, err = _replay(capsys, out, "--agent", "tests.bench_helpers:Boom", "--episode", "0", "--allow-errors")
    assert code == 0, err
    assert text.startswith("episode 0: verified; the replay raised:") and "guardian exploded" in text
    # named by its class alone, the module is the database's word only: refused, nothing imported
    code, _, err = _replay(capsys, out, "--agent", "Boom", "--episode", "0", "--allow-errors")
    assert code == 2
    assert (
        "module 'tests.bench_helpers'" in err and "--trust-modules" in err and "--agent tests.bench_helpers:Boom" in err
    )
    code, text, _ = _replay(capsys, out, "--agent", "Boom", "--episode", "1", "--allow-errors", "--trust-modules")
    assert code == 0 and "verified" in text


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    return lines[0]


def test_bad_input_is_one_line_and_exit_2(runs, tmp_path, capsys):
    cases = [
        ((tmp_path / "missing", "--agent", "lrmm", "--episode", "0"), "does not exist"),
        ((tmp_path, "--agent", "lrmm", "--episode", "0"), "holds no results.db"),
        ((runs / "fixed", "--agent", "hj", "--episode", "0"), "no run of 'hj'"),
        ((runs / "fixed", "--agent", "lrmm", "--episode", "7"), "has no episode 7"),
        ((runs / "fixed", "--agent", "lrmm", "--episode", "x"), "--episode 'x'"),
        ((runs / "fixed", "--agent", "lrmm"), "no episode chosen"),
        ((runs / "fixed", "--agent", "lrmm", "--where", "nonsense ="), "--where 'nonsense ='"),
        ((runs / "fixed", "--agent", "lrmm", "--where", "outcome = 'nothing'"), "matches"),
        ((runs / "fixed", "--agent", "lrmm", "--episode", "0", "--limit", "0"), "--limit must be >= 1"),
        ((runs / "fixed", "--agent", "lrmm", "--episode", "0", "--env", "CartPoleParallel-v0"), "ran on"),
    ]
    for argv, expected in cases:
        code, out, err = _replay(capsys, *argv)
        assert code == 2, (argv, out, err)
        assert expected in _one_line(err), (argv, err)


def test_lost_worker_episode_cannot_be_replayed(runs, tmp_path, capsys):
    shutil.copytree(runs / "fixed", tmp_path / "lost")
    con = sqlite3.connect(tmp_path / "lost" / "results.db")
    con.execute(
        "UPDATE episodes SET outcome = 'error', error_kind = 'lost_worker', error = 'lost: killed by SIGKILL' "
        "WHERE agent = 'lrmm' AND episode = 2"
    )
    con.commit()
    con.close()
    code, _, err = _replay(capsys, tmp_path / "lost", "--agent", "lrmm", "--episode", "2", "--allow-errors")
    assert code == 2 and "its worker was lost (lost: killed by SIGKILL)" in _one_line(err)


def test_newer_schema_is_refused(runs, tmp_path, capsys):
    shutil.copytree(runs / "fixed", tmp_path / "newer")
    db = tmp_path / "newer" / "results.db"
    con = sqlite3.connect(db)
    con.execute("PRAGMA user_version = 42")
    con.commit()
    con.close()
    code, _, err = _replay(capsys, tmp_path / "newer", "--agent", "lrmm", "--episode", "0")
    assert code == 2
    line = _one_line(err)
    assert str(db) in line and "schema version 42" in line and f"versions up to {SCHEMA_VERSION}" in line


def test_an_env_module_named_only_by_the_database_is_not_imported(runs, tmp_path, capsys):
    shutil.copytree(runs / "fixed", tmp_path / "evil")
    con = sqlite3.connect(tmp_path / "evil" / "results.db")
    con.execute("UPDATE runs SET config = json_set(config, '$.env_id', 'evil_module_xyz:Evil-v0')")
    con.commit()
    con.close()
    code, _, err = _replay(capsys, tmp_path / "evil", "--agent", "lrmm", "--episode", "0")
    assert code == 2
    line = _one_line(err)
    assert "module 'evil_module_xyz'" in line and "--env evil_module_xyz:Evil-v0" in line
    assert "evil_module_xyz" not in sys.modules


def test_a_module_no_longer_importable_is_named(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "gone_guard.py").write_text(
        "from rmm_guardians.base import Guardian\n\n\nclass G(Guardian):\n    name = 'g'\n\n"
        "    def act(self, obs, info):\n        return self.action_space.inactive()\n"
    )
    _run(tmp_path / "out", "gone_guard:G", "fixed:1", 1)
    (tmp_path / "gone_guard.py").unlink()
    monkeypatch.delitem(sys.modules, "gone_guard")
    monkeypatch.setattr(runner, "_CACHE", {})
    code, _, err = _replay(capsys, tmp_path / "out", "--agent", "gone_guard:G", "--episode", "0")
    assert code == 2 and "gone_guard" in _one_line(err) and "cannot be imported or built" in err


def test_a_model_file_with_another_sha256_is_refused(tmp_path, capsys, monkeypatch):
    model = tmp_path / "model.npz"
    shutil.copy(ROOT / "guardians" / "lrmm" / "models" / "dubins4d_act.npz", model)  # the shipped model
    shutil.copy(ROOT / "guardians" / "lrmm" / "models" / "dubins4d_act.decision.toml", tmp_path / "model.decision.toml")
    _run(tmp_path / "out", "lrmm", "fixed:1", 1, "Dubins4DParallel-v0", "--agent-opt", f"lrmm.model={model}")
    code, out, _ = _replay(capsys, tmp_path / "out", "--agent", "lrmm", "--episode", "0")
    assert code == 0 and out.strip() == "episode 0: verified"
    model.write_bytes(model.read_bytes() + b"\0")
    code, _, err = _replay(capsys, tmp_path / "out", "--agent", "lrmm", "--episode", "0")
    assert code == 2
    line = _one_line(err)
    assert str(model) in line and "sha256" in line and "expected" in line


def test_legacy_database_fixed_clock_runs_replay_read_only(tmp_path, capsys):
    out = tmp_path / "legacy"
    out.mkdir()
    shutil.copy(DATA / "bench_results_v0.db", out / "results.db")
    before = _digest(out / "results.db")
    code, text, err = _replay(capsys, out, "--agent", "brakes", "--episode", "0,1,2")
    assert code == 0, err
    assert text.count("verified") == 4
    assert _digest(out / "results.db") == before


def test_legacy_wall_clock_episode_says_why_it_cannot_replay(runs, tmp_path, capsys):
    shutil.copytree(runs / "wall", tmp_path / "old")
    con = sqlite3.connect(tmp_path / "old" / "results.db")
    con.execute("DROP TABLE clock_traces")
    con.execute("PRAGMA user_version = 1")
    con.commit()
    con.close()
    code, _, err = _replay(capsys, tmp_path / "old", "--agent", "lrmm", "--episode", "0")
    assert code == 2
    line = _one_line(err)
    assert "cannot be replayed" in line and "'wall' clock" in line and "predates clock traces" in line


@pytest.mark.slow
@pytest.mark.parametrize(
    ("env", "agents"),
    [
        ("Dubins4DParallel-v0", "lrmm,cbf,hj"),
        ("Dubins3DMazeParallel-v0", "lrmm,cbf"),
        ("QuadrotorRoomParallel-v0", "lrmm,cbf"),
        ("CartPoleParallel-v0", "lrmm"),
    ],
)
def test_sixteen_episodes_of_every_system_verify_on_both_clocks(env, agents, tmp_path, capsys):
    """The issue's acceptance run: 16 fresh episodes per agent, fixed and wall clock, each verified."""
    for clock in ("fixed:2", "wall"):
        out = tmp_path / clock.replace(":", "")
        _run(out, agents, clock, 16, env)
        for agent in agents.split(","):
            code, text, err = _replay(capsys, out, "--agent", agent, "--where", "1")
            assert code == 0, (env, clock, agent, text, err)
            assert text.count(": verified") == 16, text
