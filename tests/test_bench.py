import os
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from rmm_bench.cli import main
from rmm_bench.metrics import aggregate, avoidable_collisions, batch_rate, weighted_mean_std
from rmm_bench.report import AVOIDABLE_HEADER, _doomed_flags
from rmm_bench.runner import episode_seed

RUN = ["--clock", "fixed:1", "--no-progress", "--env", "Dubins4DParallel-v0"]
FAST = [*RUN, "--no-figure"]  # the tests read the database and the tables; the end-to-end test draws the figure too


def ep(i, outcome, steps=10, sim=2.0, active=0.5, compute=0.02):
    return {
        "episode": i,
        "outcome": outcome,
        "steps": steps,
        "sim_time": sim,
        "active_sim_time": active,
        "compute_time": compute,
        "decision_mean": 0.001,
        "final_speed": 1.0,
        "precompute_time": 0.0,
    }


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


def test_guardian_errors_are_failures_in_the_rates_and_counted():
    eps = [ep(0, "goal"), {"episode": 1, "outcome": "error", "qp_fallbacks": 0}, ep(2, "collision", active=2.0)]
    agg = aggregate(eps)
    assert agg["errors"] == 1 and agg["error_rate"] == pytest.approx(1 / 3)
    assert agg["goal"][0] == pytest.approx(100 / 3) and agg["collision"][0] == pytest.approx(100 / 3)
    lost = aggregate([eps[0], {"episode": 1, "outcome": "error", "error_kind": "lost_worker"}, eps[2]])
    assert lost["errors"] == 1 and lost["goal"][0] == pytest.approx(50.0)  # no result: out of the rates
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
    rows = con.execute(
        q + (" WHERE agent = ?" if agent else "") + " ORDER BY agent, episode", (agent,) if agent else ()
    ).fetchall()
    con.close()
    return rows


def _md_cells(md: str, agent: str) -> list[str]:
    (line,) = [ln for ln in md.splitlines() if ln.startswith(f"| {agent} |")]
    return [c.strip() for c in line.strip("|").split("|")]


def _pm_text(v, digits=1):
    return (
        "n/a"
        if np.isnan(v[0])
        else f"{v[0]:.{digits}f}"
        if np.isnan(v[1])
        else f"{v[0]:.{digits}f} ± {v[1]:.{digits}f}"
    )


def _digits(ms: float) -> int:
    return 3 if ms < 0.1 else 2 if ms < 10 else 1


def _check_rendered_numbers(out, aggs: dict) -> None:
    """table_I.md/.csv/.tex hold exactly the aggregation of the stored episodes."""
    import csv

    md, tex = (out / "table_I.md").read_text(), (out / "table_I.tex").read_text()
    with open(out / "table_I.csv") as fh:
        csv_rows = {r["agent"]: r for r in csv.DictReader(fh)}
    assert set(csv_rows) == set(aggs)
    for agent, agg in aggs.items():
        r = csv_rows[agent]
        assert int(r["episodes"]) == agg["episodes"] and int(r["errors"]) == agg["errors"]
        assert int(r["qp_fallbacks"]) == agg["qp_fallbacks"]
        for col, key in (
            ("compute_ms", "compute_ms"),
            ("success", "goal"),
            ("collision", "collision"),
            ("timeout", "timeout"),
            ("intervention", "intervention"),
        ):
            got = (float(r[f"{col}_mean"]), float(r[f"{col}_std"]))
            np.testing.assert_array_equal(got, agg[key])  # bit for bit (nan == nan)
        cells = _md_cells(md, agent)
        expected = [str(agg["episodes"]), _pm_text(agg["compute_ms"], _digits(agg["compute_ms"][0]))]
        if "Measured decision time [ms]" in md.splitlines()[0]:  # a fixed clock: the measured time beside
            dec = agg["decision_ms"]
            expected.append(_pm_text(dec, _digits(dec[0])))
        for k in ("goal", "collision", "timeout"):  # fewer than two batches: the Wilson 95% interval
            lo, hi = agg[f"{k}_ci"]
            wilson = agg["rate_spread"] == "wilson95" and not np.isnan(agg[k][0])
            expected.append(f"{agg[k][0]:.1f} [{lo:.1f}, {hi:.1f}]†" if wilson else _pm_text(agg[k]))
            if k == "collision" and AVOIDABLE_HEADER in md.splitlines()[0]:  # the starts were assessed
                m = agg["avoidable_collision"][0]
                lo, hi = agg["avoidable_collision_ci"]
                wilson = agg["avoidable_collision_spread"] == "wilson95" and not np.isnan(m)
                expected.append(f"{m:.1f} [{lo:.1f}, {hi:.1f}]†" if wilson else _pm_text(agg["avoidable_collision"]))
                expected.append(str(agg["doomed_starts"]))
        assert cells[3:] == expected + [_pm_text(agg["intervention"]), str(agg["errors"]), str(agg["qp_fallbacks"])]
        tex_line = [ln for ln in tex.splitlines() if ln.startswith(f"{agent} &")][0]
        assert (
            tex_line
            == " & ".join(cells[:-2]).replace("±", "$\\pm$").replace("†", "$^\\dagger$").replace("%", "\\%") + " \\\\"
        )


def test_rendered_tables_hold_the_aggregated_numbers(tmp_path):
    from rmm_bench.report import format_tables

    outcomes = ["goal"] * 32 + ["collision"] * 32 + ["goal"] * 16 + ["timeout"] * 48 + ["goal"] * 2
    eps = [ep(i, o, compute=0.01 * (1 + i % 3), active=0.1 * (i % 5)) for i, o in enumerate(outcomes)]
    eps[7] = {"episode": 7, "outcome": "error", "qp_fallbacks": 3}
    aggs = {"a": aggregate(eps), "b": aggregate(eps[:10], batch_size=4), "c": aggregate([eps[7]])}
    # by hand for "a": 130 episodes in batches of 64, 64 and 2 holding 31, 16 and 2 goals
    # (episode 7, a goal, is a guardian error: a failure in the rates)
    rates, w = np.array([31 / 64, 16 / 64, 1.0]), np.array([64, 64, 2])
    assert aggs["a"]["goal"][0] == pytest.approx(100 * (rates * w).sum() / w.sum())
    # "c": one episode, a guardian error, so a failure: rate 0 over one episode, whose 95% Wilson
    # half-width is z^2 / 2 / (1 + z^2) = 39.7%
    assert _pm_text(aggs["c"]["goal"]) == "0.0 ± 39.7" and _pm_text(aggs["c"]["intervention"]) == "n/a"
    rows = [{"agent": k, "obs": "none", "n_obst": 5, **v} for k, v in aggs.items()]
    tables = format_tables(rows)
    for ext in ("md", "csv", "tex"):
        (tmp_path / f"table_I.{ext}").write_text(tables[ext])
    _check_rendered_numbers(tmp_path, aggs)
    assert _md_cells(tables["md"], "a")[5] == f"{aggs['a']['goal'][0]:.1f} ± {aggs['a']['goal'][1]:.1f}"


def test_every_agent_end_to_end_and_report(tmp_path, capsys):
    """What only this test checks: every built-in guardian runs through the harness without an
    error, the written tables hold the aggregation of the stored rows, and ``report`` rebuilds
    the same table from the database alone.  One episode each, in this process: the worker
    pool, resuming and determinism have their own tests."""
    from rmm_bench.store import ResultsStore

    out = tmp_path / "r"
    assert (
        main(
            [
                "--agent",
                "all",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--out",
                str(out),
                "--agent-opt",
                "hj.grid_n=[32,32,16,16]",
                *RUN,
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    agents = ("lrmm", "cbf", "hj", "random", "inactive", "brakes")  # 'all' = the defaults, not the -paper presets
    rows = _db_rows(out)
    assert sorted(r[0] for r in rows) == sorted(agents) and not [r for r in rows if r[3] == "error"]
    store = ResultsStore(out / "results.db")
    inv = store.invocation()
    aggs = {a: aggregate(store.episodes(inv["run_keys"][a])) for a in agents}
    for a in agents:  # the starts' doomed flags, where the env has a test
        config = store.run_config(inv["run_keys"][a])["config"]
        aggs[a] |= avoidable_collisions(store.episodes(inv["run_keys"][a]), _doomed_flags(store, config))
    store.close()
    _check_rendered_numbers(out, aggs)
    assert (out / "outcomes.png").stat().st_size > 0
    (out / "table_I.md").unlink()
    assert main(["report", str(out)]) == 0
    rebuilt = capsys.readouterr().out
    assert rebuilt.split("Table I:")[1] == text.split("Table I:")[1]  # the same table, from the database alone
    _check_rendered_numbers(out, aggs)


def test_named_agent_sets():
    from rmm_bench.run_checks import resolve_agents as _agents
    from rmm_guardians.registry import load_guardian_class

    assert list(_agents("all")) == ["lrmm", "cbf", "hj", "random", "inactive", "brakes"]
    assert list(_agents(" paper ")) == ["lrmm-paper", "cbf-paper", "hj-paper", "random", "inactive", "brakes"]
    assert _agents("cbf-paper,inactive") == {
        "cbf-paper": load_guardian_class("cbf-paper"),
        "inactive": load_guardian_class("inactive"),
    }  # each name's class


def test_agent_options_reach_the_guardian(tmp_path):
    out = tmp_path / "o"
    assert (
        main(
            [
                "--agent",
                "random",
                "--agent-opt",
                "random.p_active=1.0",
                "--episodes",
                "2",
                "--workers",
                "1",
                "--out",
                str(out),
                *FAST,
            ]
        )
        == 0
    )
    con = sqlite3.connect(out / "results.db")
    assert all(
        a == s for a, s in con.execute("SELECT active_steps, steps - 1 FROM episodes")
    )  # all but the driver's first lap


@pytest.mark.heavy
def test_resume_after_kill_minus_nine(tmp_path, capsys):
    out = tmp_path / "k"
    cmd = [
        sys.executable,
        "-m",
        "rmm_bench.cli",
        "--agent",
        "inactive",
        "--episodes",
        "40",
        "--workers",
        "1",
        "--out",
        str(out),
        *FAST,
    ]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300  # generous: a loaded 2-core machine can start this slowly
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
    assert main(["report", str(out)]) == 0  # the killed run: what is stored, and that it was killed
    text = capsys.readouterr().out
    assert (
        f"INCOMPLETE: episodes with a result: inactive {partial} of 40 (invocation 1 was killed: it is marked running"
        in text
    )
    assert f"| inactive | none | 5 | {partial} |" in text
    assert main(cmd[3:] + ["--resume"]) == 0
    con = sqlite3.connect(out / "results.db")
    assert con.execute("SELECT status FROM invocations ORDER BY id").fetchall() == [("interrupted",), ("finished",)]
    con.close()
    rows = _db_rows(out)
    assert [r[1] for r in rows] == list(range(40))  # nothing lost, nothing duplicated
    ref = tmp_path / "ref"
    assert main(["--agent", "inactive", "--episodes", "40", "--workers", "1", "--out", str(ref), *FAST]) == 0
    assert rows == _db_rows(ref)


def test_a_raising_guardian_is_an_error_not_a_crash(tmp_path, capsys):
    out = tmp_path / "e"
    assert (
        main(
            [
                "--agent",
                "tests.bench_helpers:Boom,inactive",
                "--episodes",
                "3",
                "--workers",
                "1",
                "--out",
                str(out),
                *FAST,
            ]
        )
        == 1
    )
    con = sqlite3.connect(out / "results.db")
    errs = con.execute("SELECT outcome, error FROM episodes WHERE agent LIKE '%Boom'").fetchall()
    assert len(errs) == 3 and all(o == "error" and "guardian exploded" in e for o, e in errs)
    assert len(_db_rows(out, "inactive")) == 3


def test_episode_time_limit_is_a_failure_that_a_rerun_retries(tmp_path, capsys):
    out = tmp_path / "t"
    cmd = [
        "--agent",
        "tests.bench_helpers:Sleepy",
        "--episodes",
        "1",
        "--workers",
        "1",
        "--episode-timeout",
        "0.3",
        "--out",
        str(out),
        *FAST,
    ]
    assert main(cmd) == 1  # the episode has no result
    assert "1 episodes ended without a result" in capsys.readouterr().err
    con = sqlite3.connect(out / "results.db")
    ((outcome, kind, err, t1),) = con.execute("SELECT outcome, error_kind, error, finished FROM episodes").fetchall()
    assert outcome == "error" and kind == "timeout" and "time limit" in err
    assert main(cmd + ["--resume"]) == 1
    ((t2,),) = con.execute("SELECT finished FROM episodes").fetchall()
    assert t2 > t1  # retried, the row replaced
    assert [s for (s,) in con.execute("SELECT status FROM invocations")] == ["failed", "failed"]


def test_unknown_names_fail_before_any_work(tmp_path, capsys):
    assert main(["--agent", "lrmm,teleport", "--out", str(tmp_path / "x"), *FAST]) == 2
    err = capsys.readouterr().err
    assert "teleport" in err and "inactive" in err
    assert main(["--agent", "lrmm", "--agent-opt", "cbf.p1=1", "--out", str(tmp_path / "x"), *FAST]) == 2
    assert main(["--agent", "lrmm", "--agent-opt", "nonsense", "--out", str(tmp_path / "x"), *FAST]) == 2
    assert not (tmp_path / "x").exists()
    assert main(["--env", "Nope-v0", "--out", str(tmp_path / "x")]) == 2
    assert "--env 'Nope-v0' is not a registered Gymnasium env" in capsys.readouterr().err
    assert main(["--clock", "sundial", "--out", str(tmp_path / "x")]) == 2
    assert main(["--episodes", "0", "--out", str(tmp_path / "x")]) == 2
    assert main(["report", str(tmp_path / "nothing")]) == 2


def test_latency_sweep(tmp_path, capsys):
    out = tmp_path / "s"
    assert (
        main(
            [
                "sweep",
                "--agent",
                "inactive",
                "--latency",
                "0,50",
                "--episodes",
                "4",
                "--workers",
                "1",
                "--out",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    assert (out / "latency_sweep.png").stat().st_size > 0
    assert "| inactive |" in (out / "latency_sweep.md").read_text()
    # `report` on a sweep's directory says what the directory holds and how to rebuild its files
    capsys.readouterr()
    assert main(["report", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds a latency sweep, not a benchmark run" in err and "rmm-bench sweep" in err
    # a store with neither kind of invocation names what is missing, once
    from rmm_bench.store import ResultsStore

    empty = tmp_path / "empty"
    empty.mkdir()
    ResultsStore(empty / "results.db").close()
    assert main(["report", str(empty)]) == 2
    assert "no benchmark run recorded in" in capsys.readouterr().err


def test_a_run_says_which_episodes_it_ran_and_which_it_reused(tmp_path, capsys):
    from rmm_bench.run_command import done_line

    assert done_line(12, 0, 0.01) == "reused 12 stored episodes: none left to run"
    assert done_line(1, 0, 0.0) == "reused 1 stored episode: none left to run"
    assert done_line(0, 4, 2.345) == "finished in 2.3 s: ran 4 episodes"
    assert done_line(8, 1, 1.0) == "finished in 1.0 s: ran 1 episode, reused 8 stored"
    out = tmp_path / "u"
    cmd = ["--agent", "inactive,brakes", "--workers", "1", "--out", str(out), *FAST]
    assert main([*cmd, "--episodes", "2"]) == 0
    first = capsys.readouterr().out.splitlines()
    assert [ln for ln in first if ln.startswith("finished in ")][0].endswith(" s: ran 4 episodes")
    assert main([*cmd, "--episodes", "2"]) == 0  # answered from the store alone: no time to give
    again = capsys.readouterr().out
    assert "reused 4 stored episodes: none left to run" in again.splitlines() and "finished in" not in again
    assert main([*cmd, "--episodes", "3"]) == 0  # part reused, part run
    more = capsys.readouterr().out.splitlines()
    assert [ln for ln in more if ln.startswith("finished in ")][0].endswith(" s: ran 2 episodes, reused 4 stored")


@pytest.mark.heavy
def test_a_guardians_warning_is_said_once_per_run_with_two_workers(tmp_path):
    """The parent builds every guardian before dispatch and shows its warnings; the workers build
    theirs silently (each worker process would repeat them)."""
    (tmp_path / "loud_guard.py").write_text(
        "import warnings\n"
        "from rmm_guardians.baselines import InactiveGuardian\n\n\n"
        "class Loud(InactiveGuardian):\n"
        "    name = 'loud'\n\n"
        "    def __init__(self):\n"
        "        super().__init__()\n"
        "        warnings.warn('loud: built with a setting worth a warning', UserWarning, stacklevel=2)\n"
    )
    cmd = [sys.executable, "-m", "rmm_bench.cli", "--agent", "loud_guard:Loud"]
    cmd += ["--episodes", "4", "--workers", "2", "--out", str(tmp_path / "w"), *FAST]
    env = os.environ | {"PYTHONWARNINGS": ""}
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.count("loud: built with a setting worth a warning") == 1, proc.stderr
    assert "ran 4 episodes" in proc.stdout


def test_a_model_of_ones_own_without_a_decision_is_refused_in_one_line_naming_tune(tmp_path):
    """On an env with a shipped model and its decision, a model of one's own gets none of it: refused
    before any episode, exit 2, one line naming the command that chooses a decision; a threshold runs it."""
    import shutil

    from rmm_guardians.lrmm.model import default_model_path

    path = tmp_path / "mine.npz"
    shutil.copy(default_model_path("CartPoleParallel-v0", variant="act"), path)  # the bytes, not the decision
    out = tmp_path / "r"
    base = ["--agent", "lrmm", "--agent-opt", f"lrmm.model={path}", "--episodes", "1", "--out", str(out), *FAST]
    base += ["--env", "CartPoleParallel-v0"]  # after FAST's env: the last one given counts
    proc = subprocess.run([sys.executable, "-m", "rmm_bench.cli", *base], capture_output=True, text=True)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert f"`rmm-bench tune --env CartPoleParallel-v0 --model {path}`" in proc.stderr
    assert "--agent-opt lrmm.threshold=" in proc.stderr and not out.exists()
    assert main([*base, "--agent-opt", "lrmm.threshold=0.2"]) == 0
