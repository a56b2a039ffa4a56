import os
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from benchmarks.bench.cli import main
from benchmarks.bench.metrics import aggregate, batch_rate, weighted_mean_std
from benchmarks.bench.runner import episode_seed

FAST = ["--clock", "fixed:1", "--no-progress", "--env", "Dubins4DParallel-v0"]


def ep(i, outcome, steps=10, sim=2.0, active=0.5, compute=0.02):
    return {"episode": i, "outcome": outcome, "steps": steps, "sim_time": sim, "active_sim_time": active,
            "compute_time": compute, "decision_mean": 0.001, "final_speed": 1.0, "precompute_time": 0.0}


def test_batch_statistics_by_hand():
    # 130 episodes: batches of 64, 64 and 2 with 32, 16 and 2 goals
    outcomes = ["goal"] * 32 + ["collision"] * 32 + ["goal"] * 16 + ["timeout"] * 48 + ["goal"] * 2
    eps = [ep(i, o) for i, o in enumerate(outcomes)]
    agg = aggregate(eps)
    rates = np.array([0.5, 0.25, 1.0])
    w = np.array([64, 64, 2])
    m = (rates * w).sum() / w.sum()
    s = np.sqrt((w * (rates - m) ** 2).sum() / w.sum())
    assert agg["goal"][0] == pytest.approx(100 * m) and agg["goal"][1] == pytest.approx(100 * s)
    assert agg["total_goal"] == pytest.approx(100 * 50 / 130)
    assert agg["collision"][0] == pytest.approx(100 * (0.5 * 64) / 130)
    assert agg["compute_ms"] == pytest.approx((2.0, 0.0))
    assert agg["intervention"] == pytest.approx((25.0, 0.0))


def test_errors_are_excluded_and_counted():
    eps = [ep(0, "goal"), {"episode": 1, "outcome": "error", "qp_fallbacks": 0}, ep(2, "collision", active=2.0)]
    agg = aggregate(eps)
    assert agg["errors"] == 1 and agg["error_rate"] == pytest.approx(1 / 3)
    assert agg["goal"][0] == pytest.approx(50.0)
    assert agg["intervention"] == pytest.approx((62.5, 37.5))


def test_weighted_helpers():
    assert weighted_mean_std([1.0, 0.0], [3, 1]) == pytest.approx((0.75, np.sqrt(0.1875)))
    assert batch_rate([True] * 64 + [False] * 64) == pytest.approx((0.5, 0.5))


def test_episode_seeds_are_derived_and_distinct():
    seeds = [episode_seed(0, i) for i in range(2048)]
    assert len(set(seeds)) == 2048
    assert episode_seed(0, 5) == episode_seed(0, 5) != episode_seed(1, 5)


def _db_rows(out, agent=None):
    con = sqlite3.connect(out / "results.db")
    q = "SELECT agent, episode, seed, outcome, steps, sim_time, active_sim_time FROM episodes"
    rows = con.execute(q + (" WHERE agent = ?" if agent else "") + " ORDER BY agent, episode", (agent,) if agent else ()).fetchall()
    con.close()
    return rows


def test_every_agent_end_to_end_and_report(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["--agent", "all", "--episodes", "4", "--workers", "2", "--out", str(out),
                 "--agent-opt", "hj.grid_n=[32,32,16,16]", *FAST]) == 0
    text = capsys.readouterr().out
    for agent in ("lrmm", "cbf", "hj", "random", "inactive", "brakes"):
        assert f"| {agent} |" in text
    for f in ("table_I.md", "table_I.csv", "table_I.tex", "outcomes.png"):
        assert (out / f).stat().st_size > 0
    (out / "table_I.md").unlink()
    assert main(["report", str(out)]) == 0
    rebuilt = capsys.readouterr().out
    assert (out / "table_I.md").exists()
    assert rebuilt.split("Table I:")[1] == text.split("Table I:")[1]  # the same table, from the database alone
    rows = _db_rows(out)
    assert len(rows) == 4 * 6 and not [r for r in rows if r[3] == "error"]


def test_agent_options_reach_the_guardian(tmp_path):
    out = tmp_path / "o"
    assert main(["--agent", "random", "--agent-opt", "random.p_active=1.0", "--episodes", "2", "--workers", "1",
                 "--out", str(out), *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    assert all(a == s for a, s in con.execute("SELECT active_steps, steps - 1 FROM episodes"))  # all but the driver's first lap


def test_same_results_whatever_the_worker_count(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    assert main(["--agent", "lrmm,random", "--episodes", "8", "--workers", "1", "--out", str(a), *FAST]) == 0
    assert main(["--agent", "lrmm,random", "--episodes", "8", "--workers", "2", "--out", str(b), *FAST]) == 0
    assert _db_rows(a) == _db_rows(b)


def test_resume_after_kill_minus_nine(tmp_path):
    out = tmp_path / "k"
    cmd = [sys.executable, "-m", "benchmarks.bench.cli", "--agent", "inactive", "--episodes", "40", "--workers", "1", "--out", str(out), *FAST]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    n = 0
    while time.time() < deadline:
        time.sleep(0.05)
        if (out / "results.db").exists():
            try:
                n = len(_db_rows(out))
            except sqlite3.OperationalError:
                continue
            if n >= 5:
                break
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = len(_db_rows(out))
    assert 5 <= partial < 40
    assert subprocess.run(cmd + ["--resume"], capture_output=True).returncode == 0
    rows = _db_rows(out)
    assert [r[1] for r in rows] == list(range(40))  # nothing lost, nothing duplicated
    ref = tmp_path / "ref"
    assert main(["--agent", "inactive", "--episodes", "40", "--workers", "2", "--out", str(ref), *FAST]) == 0
    assert rows == _db_rows(ref)


def test_a_raising_guardian_is_an_error_not_a_crash(tmp_path, capsys):
    out = tmp_path / "e"
    assert main(["--agent", "tests.bench_helpers:Boom,inactive", "--episodes", "3", "--workers", "1", "--out", str(out), *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    errs = con.execute("SELECT outcome, error FROM episodes WHERE agent LIKE '%Boom'").fetchall()
    assert len(errs) == 3 and all(o == "error" and "guardian exploded" in e for o, e in errs)
    assert len(_db_rows(out, "inactive")) == 3


def test_episode_time_limit(tmp_path):
    out = tmp_path / "t"
    assert main(["--agent", "tests.bench_helpers:Sleepy", "--episodes", "1", "--workers", "1", "--episode-timeout", "0.3",
                 "--out", str(out), *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    (outcome, err), = con.execute("SELECT outcome, error FROM episodes").fetchall()
    assert outcome == "error" and "time limit" in err


def test_unknown_names_fail_before_any_work(tmp_path, capsys):
    assert main(["--agent", "lrmm,teleport", "--out", str(tmp_path / "x"), *FAST]) == 2
    err = capsys.readouterr().err
    assert "teleport" in err and "inactive" in err
    assert main(["--agent", "lrmm", "--agent-opt", "cbf.p1=1", "--out", str(tmp_path / "x"), *FAST]) == 2
    assert main(["--agent", "lrmm", "--agent-opt", "nonsense", "--out", str(tmp_path / "x"), *FAST]) == 2
    assert not (tmp_path / "x").exists()
    with pytest.raises(SystemExit):
        main(["--env", "Nope-v0", "--out", str(tmp_path / "x")])
    assert main(["--clock", "sundial", "--out", str(tmp_path / "x")]) == 2
    assert main(["--episodes", "0", "--out", str(tmp_path / "x")]) == 2
    assert main(["report", str(tmp_path / "nothing")]) == 2


def test_latency_sweep(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", "--agent", "inactive", "--latency", "0,50", "--episodes", "4", "--workers", "2", "--out", str(out), "--no-progress"]) == 0
    assert (out / "latency_sweep.png").stat().st_size > 0
    assert "| inactive |" in (out / "latency_sweep.md").read_text()


def test_ray_backend_gives_the_same_results(tmp_path):
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        assert main(["--agent", "lrmm,brakes", "--episodes", "4", "--backend", "ray", "--out", str(tmp_path / "ray"), *FAST]) == 0
    finally:
        ray.shutdown()
    assert main(["--agent", "lrmm,brakes", "--episodes", "4", "--workers", "1", "--out", str(tmp_path / "local"), *FAST]) == 0
    assert _db_rows(tmp_path / "ray") == _db_rows(tmp_path / "local")
