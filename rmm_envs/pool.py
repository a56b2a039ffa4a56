"""Running independent tasks on local worker processes or on Ray, results as they complete.

Used by ``rmm-datagen`` (one task per shard) and ``rmm-bench`` (one task per episode).  Both
yield ``fn(task)`` results in completion order and clean up on any error or Ctrl-C (local
workers terminated, pending Ray tasks cancelled).  A task whose worker dies (or, with
``task_timeout``, runs too long) is yielded as a :class:`TaskLost` and the run goes on;
``max_lost_in_a_row`` losses in a row stop it with :class:`WorkersLost`.  An exception raised
by ``fn`` itself is re-raised in the parent and stops the run, as with ``multiprocessing.Pool``.
``workers == 1`` (or a single task) runs in this process, without isolation.

Supervision, time limits and Ray's retries: :func:`run_local`, :func:`run_ray`; why:
docs/decisions/0022-worker-pool.md.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import socket
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

from rmm_envs.environment_variables import safe_path_start, safe_path_started

__all__ = ["TaskLost", "WorkersLost", "check_reachable", "describe_exit", "run_local", "run_ray"]


@dataclass(frozen=True)
class TaskLost:
    """A task that produced no result because its worker died (or was killed); ``cause`` says why."""

    task: Any
    cause: str


class WorkersLost(RuntimeError):
    """Too many tasks in a row lost their worker: the run was stopped."""


class _RemoteTraceback(Exception):
    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


def describe_exit(exitcode: int | None) -> str:
    """A worker's exit code in words (negative codes are signals)."""
    if exitcode is None:
        return "still running"
    if exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        hint = {
            "SIGKILL": " (often the out-of-memory killer)",
            "SIGSEGV": " (a crash in compiled code)",
            "SIGBUS": " (a crash in compiled code)",
            "SIGABRT": " (an abort in compiled code)",
        }.get(name, "")
        return f"killed by {name}{hint}"
    return f"exited with code {exitcode} (os._exit or sys.exit inside the task?)"


def _worker_main(fn: Callable, conn) -> None:
    """Worker loop: receive ``(index, task)``, send ``("ok", index, result)`` or ``("err", index, (exc, tb))``."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides what Ctrl-C stops
    safe_path_started()  # what its tasks start sees the current directory as usual
    while True:
        try:
            msg = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if msg is None:
            return
        idx, task = msg
        try:
            conn.send(("start", idx, None))  # the parent's time limit counts from here
        except (BrokenPipeError, EOFError, OSError):
            return
        try:
            reply = ("ok", idx, fn(task))
        except Exception as e:
            reply = ("err", idx, (e, traceback.format_exc()))
        try:
            conn.send(reply)
        except (BrokenPipeError, EOFError, OSError):
            return
        except Exception as e:  # the result or the exception does not pickle
            text = reply[2][1] if reply[0] == "err" else ""
            conn.send(
                (
                    "err",
                    idx,
                    (
                        RuntimeError(
                            f"task {idx}: its {'exception' if text else 'result'} cannot be sent "
                            f"to the parent process ({type(e).__name__}: {e})"
                        ),
                        text,
                    ),
                )
            )


_STARTUP_S = 120.0  # seconds a fresh worker may take to start before its first task's limit counts


class _Worker:
    def __init__(self, ctx, fn: Callable) -> None:
        parent, child = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_worker_main, args=(fn, child), daemon=True)
        with safe_path_start():  # the current directory is not first on its path while it starts
            self.proc.start()
        child.close()
        self.conn = parent
        self.job: tuple[int, Any] | None = None
        self.started = 0.0
        self.running = False

    def deadline(self, task_timeout: float) -> float:
        # a worker still starting up (imports, first unpickling) gets _STARTUP_S more
        return self.started + task_timeout + (0.0 if self.running else _STARTUP_S)

    def give(self, idx: int, task) -> None:
        self.job = (idx, task)
        self.started = time.monotonic()
        self.running = False  # until the worker says it started the task (after its own start-up)
        self.conn.send((idx, task))

    def stop(self, graceful: bool) -> None:
        if graceful and self.proc.is_alive():
            try:
                self.conn.send(None)
            except OSError:
                pass
            self.proc.join(5)
        if self.proc.is_alive():
            self.proc.terminate()
            self.proc.join(5)
        if self.proc.is_alive():
            self.proc.kill()
            self.proc.join()
        self.conn.close()


def run_local(
    fn: Callable, tasks: list, workers: int, *, task_timeout: float | None = None, max_lost_in_a_row: int | None = None
) -> Iterator:
    """``fn(task)`` for each task, in ``workers`` spawned processes (in this process if 1).

    Yields each result, or a :class:`TaskLost` for a task whose worker died or overran
    ``task_timeout`` seconds; raises :class:`WorkersLost` after ``max_lost_in_a_row`` lost
    tasks with no result in between (None: never).

    Supervised: each worker runs one task at a time over its own pipe, and the parent watches
    every worker's process handle, so a worker that disappears (the out-of-memory killer, a
    segfault in compiled code, ``os._exit`` or ``sys.exit`` inside a task) is noticed at once; a
    fresh worker takes its place.  ``task_timeout`` is counted from when the worker starts the
    task (a worker's start-up is not charged): the last resort for a task stuck where no
    in-process limit reaches.  An exception raised by ``fn`` is not a lost task: it is re-raised
    here with the worker's traceback as its cause, and the run stops.  With one worker (or one
    task) nothing is isolated: a task that kills its process kills the caller too.
    """
    if int(workers) != workers or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers}")
    if task_timeout is not None and not task_timeout > 0:
        raise ValueError(f"task_timeout must be > 0 seconds or None, got {task_timeout}")
    tasks = list(tasks)
    if workers == 1 or len(tasks) <= 1:
        for t in tasks:
            yield fn(t)
        return
    ctx = mp.get_context("spawn")
    todo = deque(enumerate(tasks))
    pool: list[_Worker] = []
    lost_in_a_row: list[str] = []
    graceful = False
    try:
        for _ in range(min(workers, len(tasks))):
            w = _Worker(ctx, fn)
            pool.append(w)
            w.give(*todo.popleft())
        while any(w.job is not None for w in pool):
            busy = [w for w in pool if w.job is not None]
            timeout = None
            if task_timeout is not None:
                timeout = max(0.0, min(w.deadline(task_timeout) for w in busy) - time.monotonic())
            ready = set(wait([w.conn for w in busy] + [w.proc.sentinel for w in busy], timeout))
            for w in busy:
                lost_cause = None
                if w.conn in ready or w.conn.poll():
                    try:
                        status, idx, payload = w.conn.recv()
                    except (EOFError, OSError):
                        w.proc.join(5)
                        lost_cause = f"its worker process (pid {w.proc.pid}) {describe_exit(w.proc.exitcode)}"
                    else:
                        if status == "start":
                            w.started, w.running = time.monotonic(), True
                            continue
                        if status == "err":
                            exc, tb = payload
                            raise exc from _RemoteTraceback(f"in worker process {w.proc.pid}:\n{tb}")
                        w.job = None
                        lost_in_a_row.clear()
                        if todo:
                            w.give(*todo.popleft())
                        yield payload
                        continue
                elif w.proc.sentinel in ready:
                    w.proc.join(5)
                    lost_cause = f"its worker process (pid {w.proc.pid}) {describe_exit(w.proc.exitcode)}"
                elif task_timeout is not None and time.monotonic() >= w.deadline(task_timeout):
                    w.proc.kill()
                    w.proc.join()
                    lost_cause = f"no result after {task_timeout:g} s: its worker process (pid {w.proc.pid}) was killed"
                if lost_cause is None:
                    continue
                assert w.job is not None  # w is busy: only a finished job clears it, and that continued above
                _, task = w.job
                w.job = None
                w.stop(graceful=False)
                pool.remove(w)
                lost_in_a_row.append(lost_cause)
                if todo:
                    nw = _Worker(ctx, fn)
                    pool.append(nw)
                    nw.give(*todo.popleft())
                yield TaskLost(task, lost_cause)
                if max_lost_in_a_row is not None and len(lost_in_a_row) >= max_lost_in_a_row:
                    raise WorkersLost(
                        f"{len(lost_in_a_row)} tasks in a row lost their worker with none finishing "
                        f"(last: {lost_in_a_row[-1]}); stopped"
                    )
        graceful = True
    finally:
        for w in pool:
            w.stop(graceful)


def check_reachable(address: str, timeout: float = 10.0) -> None:
    """Raise :class:`ConnectionError` naming ``address`` when nothing accepts a connection there
    within ``timeout`` seconds (``ray.init`` would otherwise retry for minutes).  ``host:port``
    or ``ray://host:port``; ``auto`` and ``local`` are Ray's own and not checked."""
    if address in ("auto", "local"):
        return
    target = address.split("://", 1)[-1]
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit():
        return  # a form Ray understands and this check does not: left to Ray
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout).close()
    except OSError as e:
        raise ConnectionError(f"cannot reach the Ray cluster at {address} ({type(e).__name__}: {e})") from None


def run_ray(
    fn: Callable, tasks: Iterable, address: str | None = None, *, max_lost_in_a_row: int | None = None
) -> Iterator:
    """``fn(task)`` for each task as Ray tasks (``address`` of a cluster, else a local Ray).

    Yields each result, or a :class:`TaskLost` for a task Ray lost twice (worker or node
    death, Ray's memory monitor); raises :class:`WorkersLost` as :func:`run_local` does.
    Ray retries a lost task once (``max_retries=1``); application errors are re-raised.  There is
    no parent-side time limit on Ray tasks: a limit inside the task (``rmm-bench``'s episode
    timer) is the only one.
    """
    try:  # lazy: Ray is an optional heavy dependency (the ray extra), loaded for the Ray backend only
        import ray
    except ImportError as e:
        raise RuntimeError("the Ray backend needs Ray: the ray extra, pip install -e '.[ray]' in a clone") from e
    if not ray.is_initialized():
        if address:
            check_reachable(address)
            ray.init(address=address)
        else:
            ray.init(num_cpus=os.cpu_count() or 1, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1, max_retries=1)(fn)
    task_of = {}
    for t in tasks:
        task_of[remote.remote(t)] = t
    pending = list(task_of)
    lost_in_a_row: list[str] = []
    try:
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                try:
                    out = ray.get(ref)
                except ray.exceptions.RayTaskError:
                    raise  # fn raised: an application error, not a lost task
                except ray.exceptions.RayError as e:
                    first = str(e).strip().splitlines()[0] if str(e).strip() else ""
                    cause = f"Ray lost it ({type(e).__name__}: {first})"[:500]
                    lost_in_a_row.append(cause)
                    yield TaskLost(task_of[ref], cause)
                    if max_lost_in_a_row is not None and len(lost_in_a_row) >= max_lost_in_a_row:
                        raise WorkersLost(
                            f"{len(lost_in_a_row)} Ray tasks in a row were lost with none finishing "
                            f"(last: {cause}); stopped"
                        ) from e
                else:
                    lost_in_a_row.clear()
                    yield out
    except BaseException:
        for ref in pending:
            ray.cancel(ref, force=True)
        raise
