"""Fault drills for rmm-bench and rmm-datagen: dead workers, stuck tasks, bad options, a raising
``stats()``, damaged databases, killed runs, and a database naming modules it must not import.

Each drill is a tiny run (a few episodes of cheap guardians, a few tiny shards) so the file
takes seconds.  Drills that would hang on a pool that misses a dead worker run under a
watchdog thread, so a regression fails instead of hanging.
"""

import json
import sqlite3
import sys
import threading
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_envs.pool import TaskLost, WorkersLost, run_local
from tests.bench_helpers import faulty_task, query

# tables and the database only: the figure has its own tests (test_bench, test_cli_figures)
FAST = ["--clock", "fixed:1", "--no-progress", "--env", "Dubins4DParallel-v0", "--no-figure"]


def within(seconds, fn):
    """``fn()``, failing the test (instead of hanging) if it has not returned after ``seconds``."""
    box = {}

    def target():
        try:
            box["value"] = fn()
        except BaseException as e:  # noqa: BLE001 - handed to the test thread
            box["error"] = e

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(seconds)
    if t.is_alive():
        pytest.fail(f"still running after {seconds} s: a dead worker was not noticed")
    if "error" in box:
        raise box["error"]
    return box["value"]


def rows(out, cols="agent, episode, outcome, error_kind, error"):
    return query(out, f"SELECT {cols} FROM episodes ORDER BY agent, episode")


def invocations(out):
    return query(out, "SELECT id, status, message FROM invocations ORDER BY id")


# ------------------------------------------------------------------ the worker pool
def test_pool_reports_dead_workers_and_finishes_the_rest():
    tasks = [("sq", i) for i in range(4)] + [("exit", 3), ("kill",)] + [("sq", 7)]
    out = within(60, lambda: list(run_local(faulty_task, tasks, 2)))
    assert sorted(r for r in out if not isinstance(r, TaskLost)) == [0, 1, 4, 9, 49]
    lost = {r.task: r.cause for r in out if isinstance(r, TaskLost)}
    assert set(lost) == {("exit", 3), ("kill",)}
    assert "exited with code 3" in lost[("exit", 3)]
    assert "killed by SIGKILL" in lost[("kill",)] and "out-of-memory" in lost[("kill",)]


def test_pool_kills_a_stuck_task_after_its_time_limit():
    # SIGALRM blocked: no in-process timer can end this task; the parent kills the worker
    out = within(60, lambda: list(run_local(faulty_task, [("hang", 60), ("sq", 3)], 2, task_timeout=1.0)))
    assert 9 in out
    (lost,) = [r for r in out if isinstance(r, TaskLost)]
    assert lost.task == ("hang", 60) and "no result after 1 s" in lost.cause


def test_pool_stops_when_every_worker_dies():
    seen = []

    def consume():
        for r in run_local(faulty_task, [("exit", 9)] * 8, 2, max_lost_in_a_row=3):
            seen.append(r)

    with pytest.raises(WorkersLost, match="3 tasks in a row lost their worker.*exited with code 9"):
        within(60, consume)
    assert len(seen) == 3 and all(isinstance(r, TaskLost) for r in seen)


def test_pool_reraises_a_task_exception_with_the_worker_traceback():
    with pytest.raises(KeyError, match="raised on purpose") as info:
        within(60, lambda: list(run_local(faulty_task, [("raise",), ("sq", 1)], 2)))
    assert "faulty_task" in str(info.value.__cause__)


# ------------------------------------------------------------------ rmm-bench: a dead worker
def test_bench_records_a_dead_worker_and_resume_retries_it(tmp_path, monkeypatch, capsys):
    out = tmp_path / "dead"
    monkeypatch.setenv("RMM_TEST_EXIT_MARKER", str(tmp_path / "exited"))  # read by the spawned workers
    cmd = ["--agent", "tests.bench_helpers:ExitOnce", "--episodes", 2, "--workers", 2, "--out", out, *FAST]
    assert within(120, lambda: main([str(c) for c in cmd])) == 1
    first = capsys.readouterr()
    last = first.err.strip().splitlines()[-1]
    assert "1 episodes ended without a result" in last and "rerun the same command" in last
    assert "INCOMPLETE: episodes with a result: tests.bench_helpers:ExitOnce 1 of 2" in first.out
    (lost,) = [r for r in rows(out) if r[2] == "error"]
    assert lost[3] == "lost_worker" and "exited with code 3" in lost[4]
    assert invocations(out)[-1][1] == "failed"

    # the marker exists now: the guardian behaves; one episode to run, so in this process
    assert main([str(c) for c in cmd] + ["--resume"]) == 0
    assert "error" not in [r[2] for r in rows(out)]
    assert [r[1] for r in invocations(out)] == ["failed", "finished"]
    ref = tmp_path / "ref"
    assert main(["--agent", "inactive", "--episodes", "2", "--workers", "1", "--out", str(ref), *FAST]) == 0
    assert rows(out, "episode, seed, outcome, steps, sim_time") == rows(ref, "episode, seed, outcome, steps, sim_time")


# ------------------------------------------------------------------ rmm-bench: bad options
BAD_OPTIONS = [
    (["--time-accel", "0"], "--time-accel 0"),
    (["--base-step", "-1"], "--base-step -1"),
    (["--episode-timeout", "-1"], "--episode-timeout"),
    (["--episode-timeout", "0"], "--episode-timeout"),
    (["--seed", "-1"], "--seed"),
    (["--agent-opt", "lrmm.threshold=7"], "--agent-opt lrmm.threshold=7"),
    (["--agent-opt", "lrmm.model=MISSING"], "--agent-opt lrmm.model="),
    (["--agent-opt", "lrmm.model=CORRUPT"], "--agent-opt lrmm.model="),
    (["--agent-opt", "lrmm.windw=3"], "--agent-opt lrmm.windw=3"),
    (["--agent-opt", "lrmm.threshold=true"], "threshold must be a number in [0, 1], got True"),
    (["--agent-opt", "lrmm.threshold=nan"], "threshold must be a number in [0, 1], got 'nan'"),
    (["--agent-opt", "lrmm.strategies=Nope"], "unknown strategy 'Nope'; the strategies are: SafestCandidate"),
    (
        ["--agent-opt", "lrmm.commit=5"],
        "unexpected keyword argument 'commit'; lrmm takes model, settings, env_id, threshold",
    ),
    (["--agent-opt", "lrmm.env_id=Dubins3DMazeParallel-v0"], "every guardian is built for the run's env (--env)"),
]


@pytest.mark.parametrize("opts, flag", BAD_OPTIONS, ids=[" ".join(o) for o, _ in BAD_OPTIONS])
def test_bad_options_exit_2_naming_the_flag_before_any_episode(tmp_path, capsys, opts, flag):
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04" + bytes(range(256)) * 4)
    opts = [o.replace("MISSING", str(tmp_path / "nope.npz")).replace("CORRUPT", str(corrupt)) for o in opts]
    out = tmp_path / "r"
    assert main(["--agent", "lrmm", "--episodes", "1", "--workers", "1", "--out", str(out), *opts, *FAST]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and flag in err, err
    assert opts[-1].split("=")[-1] in err  # the bad value
    assert not out.exists()  # nothing ran, nothing was written


@pytest.mark.parametrize("flag, value", [("--time-accel", "5"), ("--base-step", "0.3")])
def test_non_blocking_options_on_a_blocking_env_exit_2_instead_of_being_ignored(tmp_path, capsys, flag, value):
    out = tmp_path / "r"
    argv = [
        "--agent",
        "inactive",
        "--episodes",
        "1",
        "--workers",
        "1",
        "--out",
        str(out),
        "--clock",
        "fixed:1",
        "--no-progress",
        "--env",
        "Dubins4DGuarded-v0",
        flag,
        value,
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.endswith(
        f"{flag} {value}: Dubins4DGuarded-v0 steps by a fixed step per decision and takes no "
        f"{flag[2:].replace('-', '_')}; leave {flag} out, or run its non-blocking (Parallel) twin"
    ), err
    assert not out.exists()
    assert main(argv[:-2]) == 0  # the defaults are what a blocking env runs with


# ------------------------------------------------------------------ rmm-bench: stats() and --retry-errors
def test_stats_failure_is_the_guardians_error_and_retry_errors_reruns_it(tmp_path, capsys):
    out = tmp_path / "s"
    cmd = [
        "--agent",
        "tests.bench_helpers:StatsBoom,inactive",
        "--episodes",
        "2",
        "--workers",
        "1",
        "--out",
        str(out),
        *FAST,
    ]
    assert main(cmd) == 1  # guardian errors: counted as failures, and the command says so
    text = capsys.readouterr().out
    got = rows(out)
    boom = [r for r in got if r[0].endswith("StatsBoom")]
    assert [(r[2], r[3]) for r in boom] == [("error", "guardian")] * 2
    assert all("tests.bench_helpers:StatsBoom.stats() raised ZeroDivisionError: stats exploded" in r[4] for r in boom)
    assert [r[2] for r in got if r[0] == "inactive"] != ["error", "error"]
    cells = text.split("| tests.bench_helpers:StatsBoom |")[1].split("\n")[0].split("|")
    assert cells[2].strip() == "2" and cells[-3].strip() == "2"  # 2 episodes, 2 errors
    assert invocations(out)[-1][1] == "finished"

    stamps = rows(out, "agent, episode, finished")
    assert main(cmd + ["--resume"]) == 1  # guardian errors are results: nothing to run
    assert rows(out, "agent, episode, finished") == stamps
    assert main(cmd + ["--retry-errors"]) == 1  # ... unless asked
    after = dict(((a, e), f) for a, e, f in rows(out, "agent, episode, finished"))
    for a, e, f in stamps:
        assert (after[(a, e)] != f) == a.endswith("StatsBoom")


# ------------------------------------------------------------------ rmm-bench: damaged results.db
def _damage(db: Path, how: str) -> None:
    data = bytearray(db.read_bytes())
    if how == "garbage":
        data = bytearray(b"this is not a database " * 200)
    elif how == "truncated":
        data = data[: len(data) // 2]
    elif how == "page-header":  # the b-tree page header of page 2
        data[4096:4104] = b"\xff" * 8
    db.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def small_db(tmp_path_factory):
    out = tmp_path_factory.mktemp("db") / "r"
    assert main(["--agent", "inactive", "--episodes", "2", "--workers", "1", "--out", str(out), *FAST]) == 0
    return out / "results.db"


@pytest.mark.parametrize("how", ["garbage", "truncated", "page-header"])
def test_damaged_database_is_one_line_naming_the_file(tmp_path, capsys, small_db, how):
    out = tmp_path / "d"
    out.mkdir()
    db = out / "results.db"
    db.write_bytes(small_db.read_bytes())
    _damage(db, how)
    for cmd in (
        ["report", str(out)],
        ["--agent", "inactive", "--episodes", "2", "--workers", "1", "--resume", "--out", str(out), *FAST],
    ):
        assert main(cmd) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert str(db) in err and "move it aside" in err and f"mv {db} {db}.damaged" in err


# ------------------------------------------------------------------ rmm-bench report: stored rows only
def test_report_never_imports_modules_named_in_the_database(tmp_path, capsys, monkeypatch):
    out = tmp_path / "r"
    assert main(["--agent", "inactive", "--episodes", "2", "--workers", "1", "--out", str(out), *FAST]) == 0
    capsys.readouterr()
    probe = tmp_path / "probes"
    probe.mkdir()
    for mod in ("rmm_probe_guardian", "rmm_probe_env"):
        (probe / f"{mod}.py").write_text(f"open({str(tmp_path / mod)!r} + '.imported', 'w').close()\nclass G: pass\n")
    monkeypatch.syspath_prepend(str(probe))
    con = sqlite3.connect(out / "results.db")
    ((key, cfg, prov),) = con.execute("SELECT run_key, config, provenance FROM runs").fetchall()
    cfg = json.loads(cfg) | {"env_id": "rmm_probe_env:Probe-v0"}
    prov = {k: v for k, v in json.loads(prov).items() if k != "guardian"}  # as written before this was stored
    con.execute(
        "UPDATE runs SET agent = 'rmm_probe_guardian:G', config = ?, provenance = ?",
        (json.dumps(cfg), json.dumps(prov)),
    )
    con.execute("UPDATE episodes SET agent = 'rmm_probe_guardian:G'")
    con.execute("UPDATE invocations SET run_keys = ?", (json.dumps({"rmm_probe_guardian:G": key}),))
    con.commit()
    con.close()
    assert main(["report", str(out)]) == 0
    assert "| rmm_probe_guardian:G | ? | ? | 2 |" in capsys.readouterr().out
    assert not list(tmp_path.glob("*.imported"))
    assert "rmm_probe_guardian" not in sys.modules and "rmm_probe_env" not in sys.modules


# ------------------------------------------------------------------ rmm-datagen: a dead worker
@pytest.mark.slow  # rmm-bench's dead-worker drill above runs in the default suite
def test_datagen_reports_a_dead_worker_and_a_rerun_finishes(tmp_path, monkeypatch):
    from rmm_envs.risk import datagen
    from tests.bench_helpers import dying_shard_job

    cfg = dict(configs=3, samples_per_config=4, branches=3, depth=1, configs_per_shard=1, seed=5)
    out = tmp_path / "d"
    monkeypatch.setattr(datagen, "_shard_job", dying_shard_job)
    with pytest.raises(RuntimeError) as info:
        within(120, lambda: datagen.generate(datagen.DatagenConfig(**cfg), out, workers=2, progress=False))
    msg = str(info.value)
    assert "1 of 3 shards to compute were lost: shard 1 (its worker process" in msg and "exited with code 3" in msg
    assert "rerun the same command" in msg
    assert sorted(p.name for p in out.glob("shard-*.parquet")) == ["shard-00000.parquet", "shard-00002.parquet"]
    assert not (out / "manifest.json").exists()
    monkeypatch.undo()
    manifest = datagen.generate(datagen.DatagenConfig(**cfg), out, workers=1, progress=False)
    assert manifest["last_run"]["new_rows"] == 4
    ref = datagen.generate(datagen.DatagenConfig(**cfg), tmp_path / "ref", workers=1, progress=False)
    assert manifest["dataset_sha256"] == ref["dataset_sha256"]


def test_datagen_rejects_zero_workers(tmp_path):
    from rmm_envs.risk import datagen

    with pytest.raises(ValueError, match=r"workers \(--workers\) must be an integer >= 1 .*got 0"):
        datagen.generate(
            datagen.DatagenConfig(configs=2, samples_per_config=2, branches=2, depth=1, configs_per_shard=1),
            tmp_path / "z",
            workers=0,
            progress=False,
        )


@pytest.mark.slow  # a Ray cluster of its own: 10 s of wall and Ray's daemons' CPU besides
def test_ray_backend_same_results_and_a_lost_task_is_reported(tmp_path):
    try:
        import ray
    except ImportError as e:  # a pinned test dependency: its absence is a broken install, not a skip
        raise ImportError("ray is a test dependency: pip install -e '.[test]'") from e
    from rmm_envs.pool import run_ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        assert (
            main(
                ["--agent", "lrmm,brakes", "--episodes", "4", "--backend", "ray", "--out", str(tmp_path / "ray"), *FAST]
            )
            == 0
        )
        out = within(120, lambda: list(run_ray(faulty_task, [("sq", 2), ("exit", 3), ("sq", 5)])))
    finally:
        ray.shutdown()
    assert sorted(r for r in out if not isinstance(r, TaskLost)) == [4, 25]
    (lost,) = [r for r in out if isinstance(r, TaskLost)]
    assert lost.task == ("exit", 3) and "Ray lost it" in lost.cause
    assert (
        main(["--agent", "lrmm,brakes", "--episodes", "4", "--workers", "1", "--out", str(tmp_path / "local"), *FAST])
        == 0
    )
    cols = "agent, episode, seed, outcome, steps, sim_time, active_sim_time"
    assert rows(tmp_path / "ray", cols) == rows(tmp_path / "local", cols)


# ------------------------------------------------------------------ rmm-bench: how an invocation ends
@pytest.mark.parametrize(
    "exc, code, status", [(KeyboardInterrupt(), 130, "interrupted"), (ZeroDivisionError("bug"), None, "failed")]
)
def test_an_invocation_never_stays_running(tmp_path, monkeypatch, exc, code, status):
    import rmm_bench.run_execute as run_execute

    def broken(*a, **k):
        raise exc

    monkeypatch.setattr(run_execute, "execute", broken)
    out = tmp_path / "i"
    argv = ["--agent", "inactive", "--episodes", "1", "--workers", "1", "--out", str(out), *FAST]
    if code is None:
        with pytest.raises(type(exc)):
            main(argv)
    else:
        assert main(argv) == code
    ((_, got, message),) = invocations(out)
    assert got == status and message
