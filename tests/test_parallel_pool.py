"""The local worker pool's parts (rmm_envs.pool), pinned in this process where test_faults.py's
drills only see them from outside: the worker loop's protocol over its pipe, exit causes in words,
the start-up allowance of the time limit, graceful and forced stops, and the argument checks."""

import functools
import multiprocessing as mp
import multiprocessing.util  # noqa: F401 - mp.util
import os
import signal
from pathlib import Path

import pytest

from rmm_envs.pool import _STARTUP_S, TaskLost, _Worker, _worker_main, describe_exit, run_local
from tests.bench_helpers import faulty_task
from tests.test_faults import within  # fails a test that would hang (a pool that misses its end)


@pytest.mark.parametrize(
    "code, text",
    [
        (None, "still running"),
        (0, "exited with code 0 (os._exit or sys.exit inside the task?)"),
        (3, "exited with code 3 (os._exit or sys.exit inside the task?)"),
        (-signal.SIGKILL, "killed by SIGKILL (often the out-of-memory killer)"),
        (-signal.SIGSEGV, "killed by SIGSEGV (a crash in compiled code)"),
        (-signal.SIGBUS, "killed by SIGBUS (a crash in compiled code)"),
        (-signal.SIGABRT, "killed by SIGABRT (an abort in compiled code)"),
        (-signal.SIGTERM, "killed by SIGTERM"),
        (-200, "killed by signal 200"),
    ],
)
def test_exit_causes_in_words(code, text):
    assert describe_exit(code) == text


def _loop(fn, messages, close_parent=False):
    """Run the worker loop here on a pipe preloaded with ``messages``; return what it sent back."""
    parent, child = mp.Pipe(duplex=True)
    for m in messages:
        parent.send(m)
    if close_parent:
        parent.close()
    old = signal.getsignal(signal.SIGINT)

    def hung(*_):
        raise TimeoutError("the worker loop did not return within 30 s")

    old_alarm = signal.signal(signal.SIGALRM, hung)  # a loop that misses its end fails instead of hanging
    signal.setitimer(signal.ITIMER_REAL, 30.0)
    try:
        _worker_main(fn, child)
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN  # the parent decides what Ctrl-C stops
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old_alarm)
        signal.signal(signal.SIGINT, old)
    if close_parent:
        return None
    out = []
    while parent.poll():
        out.append(parent.recv())
    return out


def test_worker_loop_says_start_then_sends_each_result_until_told_to_stop():
    out = _loop(faulty_task, [(0, ("sq", 3)), (5, ("sq", 4)), None, (6, ("sq", 5))])
    assert out == [("start", 0, None), ("ok", 0, 9), ("start", 5, None), ("ok", 5, 16)]  # nothing after None


def test_worker_loop_sends_a_task_exception_with_its_traceback_and_goes_on():
    out = _loop(faulty_task, [(1, ("raise",)), (2, ("sq", 2)), None])
    assert [m[:2] for m in out] == [("start", 1), ("err", 1), ("start", 2), ("ok", 2)]
    exc, tb = out[1][2]
    assert isinstance(exc, KeyError) and exc.args == ("task raised on purpose",)
    assert "in faulty_task" in tb and tb.strip().endswith("KeyError: 'task raised on purpose'")
    assert out[3][2] == 4


def _generator(task):
    return (x for x in range(task))


def _raise_unpicklable(task):
    raise ValueError(x for x in range(task))


def test_a_result_or_exception_that_cannot_be_pickled_is_sent_as_an_error_saying_so():
    out = _loop(_generator, [(7, 3), None])
    assert [m[:2] for m in out] == [("start", 7), ("err", 7)]
    exc, tb = out[1][2]
    assert isinstance(exc, RuntimeError) and tb == ""
    assert (
        str(exc)
        == "task 7: its result cannot be sent to the parent process (TypeError: cannot pickle 'generator' object)"
    )
    out = _loop(_raise_unpicklable, [(8, 3), None])
    exc, tb = out[1][2]
    assert (
        str(exc)
        == "task 8: its exception cannot be sent to the parent process (TypeError: cannot pickle 'generator' object)"
    )
    assert "in _raise_unpicklable" in tb and "ValueError" in tb  # the original traceback, as text


def test_worker_loop_ends_quietly_when_the_parent_is_gone():
    ran = []
    # the task was sent before the parent went: the loop reads it, cannot say "start", and never runs it
    assert _loop(ran.append, [(0, "task")], close_parent=True) is None
    assert ran == []
    assert _loop(ran.append, [], close_parent=True) is None  # nothing sent: EOF at once


def test_a_worker_still_starting_gets_the_startup_allowance_on_top_of_the_time_limit():
    assert _STARTUP_S == 120.0
    w = object.__new__(_Worker)  # the deadline arithmetic only, no process
    w.started, w.running = 1000.0, False
    assert w.deadline(2.5) == 1000.0 + 2.5 + 120.0
    w.running = True
    assert w.deadline(2.5) == 1002.5


def _recv(conn):
    assert conn.poll(60), "no reply from the worker in 60 s"
    return conn.recv()


def test_graceful_stop_ends_a_worker_by_message_and_a_forced_one_by_signal():
    ctx = mp.get_context("spawn")
    a, b = _Worker(ctx, faulty_task), _Worker(ctx, faulty_task)
    try:
        assert a.proc.daemon and b.proc.daemon  # workers never outlive the parent
        a.give(0, ("sq", 6))
        assert a.job == (0, ("sq", 6)) and a.running is False
        assert _recv(a.conn) == ("start", 0, None)
        assert _recv(a.conn) == ("ok", 0, 36)
        b.give(1, ("sq", 2))
        assert _recv(b.conn) == ("start", 1, None)
        assert _recv(b.conn) == ("ok", 1, 4)
    finally:
        a.stop(graceful=True)
        b.stop(graceful=False)
    assert a.proc.exitcode == 0  # it read None and returned
    assert b.proc.exitcode == -signal.SIGTERM  # terminated
    assert a.conn.closed and b.conn.closed


def _finalized(task):
    """Leaves a file behind when its worker process exits normally (multiprocessing's exit
    finalizers run then; a worker ended by a signal leaves none)."""
    folder, i = task
    mp.util.Finalize(None, functools.partial(Path(folder, f"{i}.exited").touch), exitpriority=1)
    return i


def test_a_finished_run_stops_its_workers_gracefully(tmp_path):
    tasks = [(str(tmp_path), i) for i in range(2)]
    assert sorted(within(60, lambda: list(run_local(_finalized, tasks, 2)))) == [0, 1]  # one task per worker
    assert sorted(p.name for p in tmp_path.iterdir()) == ["0.exited", "1.exited"]


def _pid(task):
    return os.getpid(), task


def test_one_worker_or_one_task_runs_here_in_order():
    me = os.getpid()
    assert list(run_local(_pid, ["a", "b", "c"], 1)) == [(me, "a"), (me, "b"), (me, "c")]
    assert list(run_local(_pid, ["a"], 4)) == [(me, "a")]
    assert list(run_local(_pid, [], 4)) == []


@pytest.mark.parametrize(
    "kw, text",
    [
        ({"workers": 0}, "workers must be an integer >= 1, got 0"),
        ({"workers": 1.5}, "workers must be an integer >= 1, got 1.5"),
        ({"workers": 2, "task_timeout": 0}, "task_timeout must be > 0 seconds or None, got 0"),
        ({"workers": 2, "task_timeout": -1.0}, "task_timeout must be > 0 seconds or None, got -1.0"),
    ],
)
def test_bad_pool_arguments_are_refused_before_anything_runs(kw, text):
    ran = []
    with pytest.raises(ValueError) as e:
        list(run_local(ran.append, [1, 2], **kw))
    assert str(e.value) == text and ran == []


def test_task_lost_carries_the_task_and_its_cause():
    lost = TaskLost(("sq", 1), "its worker process (pid 1) killed by SIGKILL")
    assert (lost.task, lost.cause) == (("sq", 1), "its worker process (pid 1) killed by SIGKILL")
    with pytest.raises(AttributeError):
        lost.cause = "changed"  # frozen: the record of a loss is not edited


def test_remote_traceback_text_is_its_argument_or_empty():
    from rmm_envs.pool import _RemoteTraceback

    assert str(_RemoteTraceback("in worker process 7:\nTraceback ...")) == "in worker process 7:\nTraceback ..."
    assert str(_RemoteTraceback()) == ""


_MARK = "as imported"


def _mark(task):
    return _MARK


def test_workers_are_fresh_spawned_processes_not_forks_of_the_caller():
    global _MARK
    _MARK = "changed in the caller"  # a forked worker would see this; a spawned one imports the module afresh
    try:
        assert within(60, lambda: list(run_local(_mark, [0, 1], 2))) == ["as imported", "as imported"]
    finally:
        _MARK = "as imported"


def _after(task):
    """("first", folder) waits until ("second", folder) has finished, then 0.5 s more."""
    import time

    which, folder = task
    mark = Path(folder, "second.done")
    if which == "second":
        mark.touch()
        return "second"
    t0 = time.monotonic()
    while not mark.exists() and time.monotonic() - t0 < 30:
        time.sleep(0.01)
    time.sleep(0.5)
    return "first"


def test_results_come_in_completion_order_past_a_busy_worker(tmp_path):
    # the first worker is busy until after the second has answered: that answer must not wait behind it
    out = within(60, lambda: list(run_local(_after, [("first", str(tmp_path)), ("second", str(tmp_path))], 2)))
    assert out == ["second", "first"]


def test_a_run_stopped_by_a_task_error_terminates_its_workers(tmp_path):
    """On an error the workers are terminated (no graceful exit: an idle worker's exit finalizers do not run)."""
    with pytest.raises(KeyError):
        within(60, lambda: list(run_local(_finalized_or_raise, [(str(tmp_path), 0), (str(tmp_path), "raise")], 2)))
    assert list(tmp_path.iterdir()) == []


def _finalized_or_raise(task):
    if task[1] == "raise":
        import time

        time.sleep(0.2)  # let the other worker finish its task first and wait, idle, for the next
        raise KeyError("raised on purpose")
    return _finalized(task)


def test_stopping_after_lost_tasks_names_the_last_cause():
    from rmm_envs.pool import WorkersLost

    seen = []

    def consume():
        for r in run_local(faulty_task, [("exit", 9)] * 6, 2, max_lost_in_a_row=3):
            seen.append(r)

    with pytest.raises(WorkersLost) as e:
        within(60, consume)
    assert len(seen) == 3 and len({r.cause for r in seen}) == 3  # three workers, three pids
    assert str(e.value) == f"3 tasks in a row lost their worker with none finishing (last: {seen[-1].cause}); stopped"
