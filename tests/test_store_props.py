"""What a rerun and a report read back from the results store (``benchmarks/bench/store.py``).

For any set of stored episodes (any indices, outcomes and error kinds, two runs in one file):
``episodes(key, n)`` is exactly the stored rows of that run with index ``0 .. n-1``, in order;
``done_episodes`` is what a rerun skips (everything but the retried failures, and guardian
errors too with ``retry_errors``); ``plan_tasks`` then asks for exactly the rest of ``0 .. n-1``;
and a stored result is replaced only where it is an error."""

from __future__ import annotations

import contextlib
import os
import sqlite3
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rmm_bench.config import AgentRun, EpisodeResult
from rmm_bench.run_plan import plan_tasks
from rmm_bench.runner import episode_seed
from rmm_bench.store import EPISODE_FIELDS, RETRIED_ERRORS, ResultsStore

RUNS = {
    a: AgentRun(
        agent=a,
        agent_kwargs={},
        env_id="Dubins4DGuarded-v0",
        env_kwargs={},
        seed=s,
        episode_timeout=60.0,
        charge_precompute=False,
    )
    for a, s in (("inactive", 0), ("brakes", 5))
}
KINDS = ("goal", "collision", "timeout", "error:guardian", "error:timeout", "error:lost_worker")


def _result(run: AgentRun, episode: int, kind: str, tag: float = 0.0, finished: float = 0.0) -> EpisodeResult:
    outcome, _, err = kind.partition(":")
    return EpisodeResult(
        run_key=run.key,
        episode=episode,
        agent=run.agent,
        seed=episode_seed(run.seed, episode),
        outcome=outcome,
        steps=episode + 1,
        sim_time=tag,
        error=f"failed ({err})" if err else None,
        error_kind=err or None,
        finished=finished,
    )


stored = st.dictionaries(st.integers(0, 24), st.sampled_from(KINDS), max_size=20)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a=stored, b=stored, n=st.integers(0, 26), retry=st.booleans())
def test_reads_are_exactly_the_stored_episodes_below_n(tmp_path, a, b, n, retry):
    path = tmp_path / "results.db"
    path.unlink(missing_ok=True)
    store = ResultsStore(path)
    try:
        for agent, eps in (("inactive", a), ("brakes", b)):
            run = RUNS[agent]
            store.ensure_run(run.key, agent, run.as_dict(), {})
            for t, (i, kind) in enumerate(sorted(eps.items(), key=lambda kv: -kv[0])):  # finished out of order
                store.add_episode(_result(run, i, kind, finished=float(t)))
        for agent, eps in (("inactive", a), ("brakes", b)):
            key = RUNS[agent].key
            rows = store.episodes(key, n)
            assert [r["episode"] for r in rows] == sorted(i for i in eps if i < n)
            assert all(r["run_key"] == key and r["agent"] == agent for r in rows)
            assert [r["outcome"] for r in rows] == [eps[i].partition(":")[0] for i in sorted(eps) if i < n]
            assert [r["episode"] for r in store.episodes(key)] == sorted(eps)
            skip = {
                i
                for i, k in eps.items()
                if not (k.startswith("error") and (retry or k.partition(":")[2] in RETRIED_ERRORS))
            }
            assert store.done_episodes(key, retry_errors=retry) == skip
        tasks = plan_tasks(store, RUNS, n, workers=1, backend="local", retry_errors=retry)
        for agent, eps in (("inactive", a), ("brakes", b)):
            mine = [t for t in tasks if t.run_key == RUNS[agent].key]
            want = [
                i
                for i in range(n)
                if i not in eps
                or (eps[i].startswith("error") and (retry or eps[i].partition(":")[2] in RETRIED_ERRORS))
            ]
            assert [t.episode for t in mine] == want
            assert [t.seed for t in mine] == [episode_seed(RUNS[agent].seed, i) for i in want]
    finally:
        store.close()


@pytest.mark.parametrize(
    "first, second, kept",
    [
        ("goal", "collision", "goal"),  # a result is never overwritten
        ("error:guardian", "goal", "goal"),  # an error is (a retry)
        ("error:timeout", "collision", "collision"),
        ("error:lost_worker", "error:timeout", "error:timeout"),
        ("timeout", "error:lost_worker", "timeout"),
    ],
)
def test_a_stored_result_is_replaced_only_where_it_is_an_error(tmp_path, first, second, kept):
    store = ResultsStore(tmp_path / "results.db")
    run = RUNS["inactive"]
    store.add_episode(_result(run, 3, first, tag=1.0))
    store.add_episode(_result(run, 3, second, tag=2.0))
    (row,) = store.episodes(run.key)
    assert (row["outcome"], row["error_kind"]) == (kept.partition(":")[0], kept.partition(":")[2] or None)
    assert row["sim_time"] == (1.0 if kept == first else 2.0)
    store.close()
    with sqlite3.connect(tmp_path / "results.db") as db:  # one row, the file holds no duplicate
        assert db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0] == 1


@contextlib.contextmanager
def _sleeping_child():
    """A live process of this user that any signal but 0 would end (SIGHUP restored to its default
    first), running until the block ends."""
    child = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import signal, time; signal.signal(signal.SIGHUP, signal.SIG_DFL); "
            "print('ready', flush=True); time.sleep(60)",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout.readline() == "ready\n"
        yield child
    finally:
        child.kill()
        child.wait()
        child.stdout.close()


# ------------------------------------------------------------------ opening, errors, older files, stale invocations
def test_opening_makes_the_folder_and_a_wal_database(tmp_path):
    store = ResultsStore(tmp_path / "a" / "b" / "results.db")
    assert store.db.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert store.db.execute("PRAGMA synchronous").fetchone()[0] == 1  # NORMAL
    cols = [r[1] for r in store.db.execute("PRAGMA table_info(episodes)")]
    assert cols == list(EPISODE_FIELDS)
    assert [r[1] for r in store.db.execute("PRAGMA table_info(episodes)") if r[5]] == ["run_key", "episode"]  # the key
    inv = [r[1] for r in store.db.execute("PRAGMA table_info(invocations)")]
    assert inv == [
        "id",
        "created",
        "kind",
        "args",
        "run_keys",
        "episodes",
        "status",
        "pid",
        "host",
        "updated",
        "message",
    ]
    store.close()
    ResultsStore(tmp_path / "a" / "b" / "results.db").close()  # opening again changes nothing
    with sqlite3.connect(tmp_path / "a" / "b" / "results.db") as db:
        assert [r[1] for r in db.execute("PRAGMA table_info(episodes)")] == list(EPISODE_FIELDS)


def _damaged(p, text: str) -> str:
    """The one line for a damaged file: the episodes are lost to rmm-bench unless exported first, and how."""
    return (
        f"{p} is damaged or not a results database ({text}); rmm-bench cannot read the episodes it holds. Export "
        f"what is still readable first (sqlite3 {p} .recover > {p}.sql, with the sqlite3 shell), then move it "
        f"aside (mv {p} {p}.damaged) and rerun: the run starts afresh in a new database, and the episodes of "
        f"the old one are lost to rmm-bench"
    )


@pytest.mark.parametrize(
    "text, start, status",
    [
        (
            "database or disk is full",
            "cannot write {p} (database or disk is full): the disk is full; free disk space, then "
            "the stored episodes are kept: rerun the same command",
            1,
        ),
        (
            "database is locked",
            "{p} is locked by another process (database is locked); wait for the other rmm-bench command "
            "to finish, or use another --out; the database is intact",
            1,
        ),
        (
            "database is busy\nretry",
            "{p} is locked by another process (database is busy retry); wait for the other rmm-bench "
            "command to finish, or use another --out; the database is intact",
            1,
        ),
        ("file is not a database", None, 2),
    ],
)
def test_each_database_error_is_one_line_saying_what_to_do(tmp_path, text, start, status):
    store = ResultsStore(tmp_path / "results.db")
    e = store._error(sqlite3.OperationalError(text))
    expected = _damaged(store.path, text) if start is None else start.format(p=store.path)
    assert type(e).__name__ == "ResultsDatabaseError" and str(e) == expected and "\n" not in str(e)
    assert e.status == status
    store.close()


def test_a_file_that_is_not_a_database_is_refused_by_name(tmp_path):
    path = tmp_path / "results.db"
    path.write_bytes(b"not a database at all" * 200)
    with pytest.raises(Exception) as e:
        ResultsStore(path)
    assert type(e.value).__name__ == "ResultsDatabaseError"
    assert str(e.value) == _damaged(path, "file is not a database")
    assert e.value.status == 2


def test_a_database_written_before_error_kinds_and_invocation_bookkeeping_is_brought_up_to_date(tmp_path):
    """A file of the first format (no ``error_kind``, invocations without pid/host/updated/message,
    status ``done``): its error rows get their kind from the message, ``done`` reads ``finished``."""
    path = tmp_path / "results.db"
    old_fields = {k: v for k, v in EPISODE_FIELDS.items() if k != "error_kind"}
    with sqlite3.connect(path) as db:
        db.executescript(f"""
            CREATE TABLE runs (run_key TEXT PRIMARY KEY, agent TEXT NOT NULL, created REAL, config TEXT NOT NULL,
                provenance TEXT NOT NULL);
            CREATE TABLE episodes ({", ".join(f"{k} {v}" for k, v in old_fields.items())}, PRIMARY KEY (run_key, episode));
            CREATE TABLE invocations (id INTEGER PRIMARY KEY AUTOINCREMENT, created REAL, kind TEXT, args TEXT,
                run_keys TEXT, episodes INTEGER, status TEXT);
            INSERT INTO invocations (created, kind, args, run_keys, episodes, status)
                VALUES (1, 'run', '{{}}', '{{}}', 2, 'done');
            INSERT INTO invocations (created, kind, args, run_keys, episodes, status)
                VALUES (2, 'run', '{{}}', '{{}}', 2, 'failed');
        """)
        for i, (outcome, error) in enumerate(
            (("goal", None), ("error", "EpisodeTimeout: over 60 s"), ("error", "boom"))
        ):
            db.execute(
                "INSERT INTO episodes (run_key, episode, agent, seed, outcome, error) VALUES (?, ?, ?, ?, ?, ?)",
                ("k", i, "a", i, outcome, error),
            )
    store = ResultsStore(path)
    rows = store.episodes("k")
    assert [r["error_kind"] for r in rows] == [None, "timeout", "guardian"]
    assert store.done_episodes("k") == {0, 2}  # the timeout is retried, the guardian error kept
    assert [store.invocation(i)["status"] for i in (1, 2)] == ["finished", "failed"]
    assert store.invocation(1)["pid"] is None and store.invocation(1)["state"] == "finished"
    store.close()


def test_only_a_running_invocation_of_a_dead_process_on_this_host_is_stale(tmp_path):
    import socket

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a process id that no longer runs
    store = ResultsStore(tmp_path / "results.db")
    host = socket.gethostname()
    with _sleeping_child() as live:
        rows = [
            ("running", dead.pid, host),
            ("running", live.pid, host),
            ("running", dead.pid, host + "-elsewhere"),
            ("finished", dead.pid, host),
            ("running", None, host),
        ]
        ids = []
        for status, pid, h in rows:
            i = store.add_invocation("run", {}, {}, 1)
            store.db.execute("UPDATE invocations SET status = ?, pid = ?, host = ? WHERE id = ?", (status, pid, h, i))
            ids.append(i)
        store.db.commit()
        assert [store.invocation(i)["state"] for i in ids] == ["stale", "running", "running", "finished", "running"]
        assert store.mark_stale_invocations() == 1
    inv = store.invocation(ids[0])
    assert (inv["status"], inv["state"]) == ("interrupted", "interrupted")
    assert inv["message"] == f"its process {dead.pid} ended without recording an end (killed)"
    assert store.invocation(ids[1])["status"] == "running"
    store.close()


def test_a_live_process_is_only_asked_whether_it_exists():
    """``pid_alive`` sends signal 0 (existence check): a live process is reported alive and left
    running; a process of another user is alive too (permission denied is an answer)."""
    from rmm_bench.store import pid_alive

    with _sleeping_child() as child:
        assert pid_alive(child.pid) is True
        with pytest.raises(subprocess.TimeoutExpired):  # not signalled: still sleeping
            child.wait(timeout=0.5)
    assert pid_alive(child.pid) is False
    # another user's process: pid 1 seen from an unprivileged process (this one, or a child that
    # drops root's privileges first; after a first call, so that everything it imports is loaded)
    drop = "os.setgid(65534); os.setuid(65534); " if os.getuid() == 0 else ""
    code = f"import os; from rmm_bench.store import pid_alive; pid_alive(os.getpid()); {drop}print(pid_alive(1))"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=os.getcwd(), check=True)
    assert r.stdout.strip() == "True"


def test_a_folder_in_place_of_the_file_is_refused_by_name(tmp_path):
    (tmp_path / "results.db").mkdir()
    with pytest.raises(Exception) as e:
        ResultsStore(tmp_path / "results.db")
    path = tmp_path / "results.db"
    assert type(e.value).__name__ == "ResultsDatabaseError" and str(e.value) == (
        f"cannot open {path} (unable to open database file): it is a directory; choose another --out"
    )
    assert e.value.status == 2


def test_quick_check_problems_are_quoted_and_the_file_is_let_go(tmp_path):
    """A file whose schema reads but whose data pages are damaged: quick_check lists problems (it
    does not fail), the message quotes them, and the connection is closed (the file can be moved
    aside at once)."""
    path = tmp_path / "results.db"
    store = ResultsStore(path)
    run = RUNS["inactive"]
    for i in range(200):
        store.add_episode(_result(run, i, "goal"))
    store.db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    store.close()
    data = bytearray(path.read_bytes())
    for page in range(2, 7):  # the b-tree page headers of pages 3 to 7 (page 1 holds the schema)
        data[4096 * page : 4096 * page + 8] = b"\xff" * 8
    path.write_bytes(bytes(data))
    db = sqlite3.connect(path)
    problems = [r[0] for r in db.execute("PRAGMA quick_check(5)")]
    db.close()
    assert problems != ["ok"] and "btreeInitPage" in problems[0]
    with pytest.raises(Exception) as e:
        ResultsStore(path)
    text = "; ".join(problems)[:300].replace("\n", " ")
    assert str(e.value) == _damaged(path, text) and e.value.status == 2
    if os.path.isdir("/proc/self/fd"):
        open_files = {
            os.path.realpath(f"/proc/self/fd/{fd}")
            for fd in os.listdir("/proc/self/fd")
            if os.path.exists(f"/proc/self/fd/{fd}")
        }
        assert str(path.resolve()) not in open_files
