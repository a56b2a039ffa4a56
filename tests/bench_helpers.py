"""Guardians that misbehave, for the benchmark's error paths."""

import time

from rmm_guardians.base import Guardian


class Boom(Guardian):
    name = "boom"

    def reset(self, **kw):
        super().reset(**kw)
        self.n = 0

    def act(self, obs, info):
        self.n += 1
        if self.n == 3:
            raise RuntimeError("guardian exploded")
        return self.action_space.inactive()


class Sleepy(Guardian):
    name = "sleepy"

    def act(self, obs, info):
        time.sleep(0.05)
        return self.action_space.inactive()


# ---------------------------------------------------------------- fault drills (tests/test_faults.py)
import os  # noqa: E402
import signal  # noqa: E402


def faulty_task(task):
    """A task for the worker pools: ``("exit", n)`` calls ``os._exit(n)``, ``("kill",)`` SIGKILLs its
    own process, ``("hang", s)`` sleeps with SIGALRM blocked, ``("raise",)`` raises; else squares."""
    kind = task[0]
    if kind == "exit":
        os._exit(task[1])
    if kind == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    if kind == "hang":
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGALRM})
        time.sleep(task[1])
    if kind == "raise":
        raise KeyError("task raised on purpose")
    return task[1] ** 2


class ExitOnce(Guardian):
    """Kills its worker process with ``os._exit(3)`` in the first ``act`` of the run: the first
    episode to get here creates the marker file named by ``RMM_TEST_EXIT_MARKER``."""

    name = "exit-once"

    def act(self, obs, info):
        import multiprocessing

        marker = os.environ["RMM_TEST_EXIT_MARKER"]
        if multiprocessing.parent_process() is None:  # never kill the test process itself
            return self.action_space.inactive()
        try:
            fd = os.open(marker, os.O_CREAT | os.O_EXCL)
        except FileExistsError:
            return self.action_space.inactive()
        os.close(fd)
        os._exit(3)


class StatsBoom(Guardian):
    """Acts like ``inactive``; its ``stats()`` raises."""

    name = "stats-boom"

    def act(self, obs, info):
        return self.action_space.inactive()

    def stats(self):
        raise ZeroDivisionError("stats exploded")


def dying_shard_job(job):
    """``rmm_envs.risk.datagen._shard_job`` whose worker dies (``os._exit(3)``) on shard 1."""
    import multiprocessing

    from rmm_envs.risk import datagen

    if job[2] == 1 and multiprocessing.parent_process() is not None:
        os._exit(3)
    return datagen._shard_job(job)


class Threaded(Guardian):
    """Acts like ``inactive``; takes ``threads`` like the HJ guardian and reports what it got
    (0 for None) and ``RMM_HJ_THREADS`` as its process sees it (-1 when unset)."""

    name = "threaded"

    def __init__(self, margin: float = 0.0, threads: int | None = None):
        super().__init__()
        self.threads = threads

    def act(self, obs, info):
        return self.action_space.inactive()

    def stats(self):
        return {"threads": self.threads or 0, "env_threads": int(os.environ.get("RMM_HJ_THREADS", -1))}


class Counting(Guardian):
    """Acts like ``inactive``; its ``stats()`` counts its decisions of the episode (``decisions``),
    a counter no built-in guardian reports."""

    name = "counting"

    def reset(self, **kw):
        super().reset(**kw)
        self.decisions = 0

    def act(self, obs, info):
        self.decisions += 1
        return self.action_space.inactive()

    def stats(self):
        return {"decisions": self.decisions}


def query(out, sql: str) -> list[tuple]:
    """The rows of one SQL query on the results database in ``out`` (closed again at once)."""
    import sqlite3

    con = sqlite3.connect(out / "results.db")
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()
