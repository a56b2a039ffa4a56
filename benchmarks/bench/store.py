"""The results store: an embedded SQLite database (``results.db``).

Tables:

* ``runs``: one row per (agent, configuration): ``run_key`` (a hash of everything that
  determines an episode's result except the episode index), the agent, the full
  configuration and provenance (package version, git revision, command line, Python, and the
  guardian's observation type and the env's obstacle count, which ``report`` prints without
  importing anything named in the database).
* ``episodes``: one row per episode, keyed by ``(run_key, episode)``, committed as soon as it
  ends (WAL journal), so killing a run loses at most the episodes in flight and a rerun skips
  what is stored.  An episode that failed has outcome ``error``, the message in ``error`` and
  its kind in ``error_kind``:

  - ``guardian``: the guardian raised (in ``reset``, ``act`` or ``stats``) or returned an
    action the env refused.  A result about the guardian: kept by a rerun, retried only with
    ``--retry-errors``.
  - ``timeout`` (over ``--episode-timeout``), ``lost_worker`` (the worker process died or
    was killed), ``input_changed`` (a file the run reads, such as a model, changed while it
    ran) and ``env`` (the worker could not register or make the env the parent made, a
    ``module:Id`` import or an entry point that fails there; or the env itself raised in its
    ``reset`` or ``step``, its driver for example): failures of the run, not results.  Every
    rerun retries them, replacing the row.

* ``clock_traces`` (schema version 2): for an episode of a clocked run (a non-blocking env
  under a ``wall`` or ``cpu`` clock), every lap the non-blocking wrapper's clock returned, in
  order, keyed by ``(run_key, episode)`` like its row: float64 values, little-endian, their
  bytes shuffled (all first bytes, then all second bytes, ...) and zlib-compressed
  (``codec`` names this), ``n`` the count.  What ``rmm-bench replay`` plays back to
  re-simulate the episode bit for bit; stored beside the row, never part of a run's key.
* ``starts`` (schema version 3): per world (:func:`rmm_envs.starts.world_key`: the env, its
  options but the clock's, the run's seed) and episode, the episode seed, the start's
  fingerprint, and whether the start was doomed (1), avoidable (0) or not assessed (NULL), by
  which test (``method``) in how many seconds.  Computed once per episode by the command that
  first runs the world, shared by every agent's row; each row also keeps its own start's
  fingerprint in ``episodes.start`` (NULL in rows stored before version 3).
* ``parts`` (schema version 4): in a database written by ``rmm-bench merge``, one row per
  input it joined (``source``: the file as named on the command line): the host, package
  version, git revision, command line and shard of the command that ran its episodes, when it
  started and finished, how many episodes it brought and its run keys, and when it was merged.
  Empty in a database written by runs alone (their provenance is in ``runs``).
* ``invocations``: each ``rmm-bench`` command: its arguments, run keys, episode count, the
  process id and host that ran it, and its status: ``running`` while it runs, then
  ``finished`` (every requested episode has a result), ``interrupted`` (Ctrl-C, or found
  dead: a ``running`` invocation whose process no longer exists on this host was killed) or
  ``failed`` (stopped on an error, or episodes left without a result; ``message`` says why).
  ``rmm-bench report DIR`` rebuilds exactly one command's table from it.

A file that cannot be used is reported as :class:`ResultsDatabaseError`: one line naming the
file, what went wrong and what to do, never a raw SQLite traceback, and its ``status``, the
exit status (:mod:`rmm_envs.os_errors`).  The causes are told apart, because only one of them
means the stored episodes are gone:

* not writable (the file, its directory or its file system is read-only for this user), or
  ``--out`` is not a directory: status 2; the database is intact, change the path or the
  permissions;
* the disk is full, a file reached the size limit (``ulimit -f``), another I/O error on a
  database whose integrity check passes: status 1; the stored episodes are kept (SQLite
  commits atomically), rerun the same command once the cause is fixed;
* locked by another process for over 30 s: status 1; wait for the other command;
* truly damaged (its integrity check fails, or it is not a SQLite database): status 2; the
  only case that suggests moving the file aside, saying that the episodes it holds are lost
  to ``rmm-bench`` unless exported first, and how (the ``sqlite3`` shell's ``.recover``).

The whole file is checked (``PRAGMA quick_check``, milliseconds for a full Table I run) when
it is opened.

Schema versions.  The layout's version is SQLite's ``PRAGMA user_version``; :data:`MIGRATIONS`
lists, in order, what brings a database from each version to the next (version 0 is a new
file or one written before versions existed, whose columns were added by probing).  Opening a
store for writing applies the missing migrations in one transaction, so a database is at a
version or at the one before, never in between; a database of a newer version than
:data:`SCHEMA_VERSION` is refused, one line naming the file, its version and the newest this
code knows (it may hold columns this code would drop).  ``ResultsStore(path, read_only=True)``
opens the file through a read-only URI (``file:...?mode=ro``): it never migrates nor commits,
and reads an older layout as it is (a column it lacks is absent from the rows, an episode of a
database without ``clock_traces`` has no trace).
"""

from __future__ import annotations

import json
import os
import socket
import time
import zlib
from collections.abc import Sequence

from rmm_bench.config import EpisodeResult
from rmm_bench.store_open import StoreConnection
from rmm_bench.store_schema import (
    _COMMAND_NAMES,
    EPISODE_FIELDS,
    MIGRATIONS,
    RETRIED_ERRORS,
    SCHEMA_VERSION,
    TRACE_CODEC,
    ResultsDatabaseError,
    decode_laps,
    encode_laps,
    pid_alive,
    results_database,
)
from rmm_bench.store_schema import guarded as _guarded
from rmm_envs.os_errors import BAD_INPUT

__all__ = [
    "EPISODE_FIELDS",
    "MIGRATIONS",
    "RETRIED_ERRORS",
    "SCHEMA_VERSION",
    "TRACE_CODEC",
    "ResultsDatabaseError",
    "ResultsStore",
    "decode_laps",
    "encode_laps",
    "pid_alive",
    "results_database",
]


class ResultsStore(StoreConnection):
    """The results database of one run directory (see the module docstring): what a command
    stores and reads; opening, checks and errors come from :class:`StoreConnection`."""

    # runs
    @_guarded
    def ensure_run(self, run_key: str, agent: str, config: dict, provenance: dict) -> None:
        self._writable()
        self.db.execute(
            "INSERT OR IGNORE INTO runs VALUES (?, ?, ?, ?, ?)",
            (run_key, agent, time.time(), json.dumps(config, sort_keys=True), json.dumps(provenance, sort_keys=True)),
        )
        self.db.commit()

    @_guarded
    def run_config(self, run_key: str) -> dict:
        row = self.db.execute("SELECT config, provenance, agent FROM runs WHERE run_key = ?", (run_key,)).fetchone()
        if row is None:
            raise LookupError(f"run {run_key} is not recorded in {self.path}")
        return {"config": json.loads(row[0]), "provenance": json.loads(row[1]), "agent": row[2]}

    @_guarded
    def runs_of(self, agent: str) -> list[dict]:
        """The stored runs of ``agent``, newest first: ``run_key``, ``config``, ``provenance``, ``created``."""
        rows = self.db.execute(
            "SELECT run_key, config, provenance, created FROM runs WHERE agent = ? ORDER BY created DESC, rowid DESC",
            (agent,),
        ).fetchall()
        return [
            {"run_key": k, "config": json.loads(c), "provenance": json.loads(p), "created": t} for k, c, p, t in rows
        ]

    @_guarded
    def superseded_runs(self, run_key: str, config: dict) -> list[dict]:
        """Other stored runs of ``config`` but for the files read (``inputs``): ``run_key``,
        their ``inputs`` and how many ``episodes`` they hold; none if ``run_key`` itself is stored."""
        if self.db.execute("SELECT 1 FROM runs WHERE run_key = ?", (run_key,)).fetchone():
            return []
        base = {k: v for k, v in config.items() if k != "inputs"}
        out = []
        for key, stored in self.db.execute(
            "SELECT run_key, config FROM runs WHERE agent = ?", (config["agent"],)
        ).fetchall():
            stored = json.loads(stored)
            if {k: v for k, v in stored.items() if k != "inputs"} == base:
                n = self.db.execute("SELECT COUNT(*) FROM episodes WHERE run_key = ?", (key,)).fetchone()[0]
                out.append({"run_key": key, "inputs": stored.get("inputs", {}), "episodes": int(n)})
        return out

    # episodes
    @_guarded
    def done_episodes(self, run_key: str, retry_errors: bool = False) -> set[int]:
        """Episodes a rerun skips: all stored ones but the retried failures (and guardian errors if ``retry_errors``)."""
        q = "SELECT episode FROM episodes WHERE run_key = ? AND "
        if retry_errors:
            q += "outcome != 'error'"
        else:
            q += f"NOT (outcome = 'error' AND COALESCE(error_kind, 'guardian') IN ({', '.join('?' * len(RETRIED_ERRORS))}))"
        return {r[0] for r in self.db.execute(q, (run_key,) + (() if retry_errors else RETRIED_ERRORS))}

    @_guarded
    def add_episode(
        self, result: EpisodeResult, invocation: int | None = None, clock_trace: Sequence[float] | None = None
    ) -> None:
        """Store an episode; it replaces a stored row only if that row is an error (a retry).
        ``clock_trace``: the laps of its clock (a clocked run), stored with the row in one
        transaction; a replaced row's old trace goes with it."""
        self._writable()
        row = result.as_row()
        keys = list(EPISODE_FIELDS)
        vals = [row[k] for k in keys]
        update = ", ".join(f"{k} = excluded.{k}" for k in keys if k not in ("run_key", "episode"))
        cur = self.db.execute(
            f"INSERT INTO episodes ({', '.join(keys)}) VALUES ({', '.join('?' * len(keys))}) "
            f"ON CONFLICT (run_key, episode) DO UPDATE SET {update} WHERE episodes.outcome = 'error'",
            vals,
        )
        if cur.rowcount:  # the row was written (new, or a retried error): its trace with it
            if clock_trace is None:
                self.db.execute(
                    "DELETE FROM clock_traces WHERE run_key = ? AND episode = ?", (result.run_key, result.episode)
                )
            else:
                self.db.execute(
                    "INSERT OR REPLACE INTO clock_traces (run_key, episode, codec, n, laps) VALUES (?, ?, ?, ?, ?)",
                    (result.run_key, result.episode, TRACE_CODEC, len(clock_trace), encode_laps(clock_trace)),
                )
        if invocation is not None:
            self.db.execute("UPDATE invocations SET updated = ? WHERE id = ?", (time.time(), invocation))
        self.db.commit()

    def has_traces(self) -> bool:
        """Whether this database has the ``clock_traces`` table (schema version 2 on)."""
        return self._table_exists("clock_traces")

    @_guarded
    def clock_trace(self, run_key: str, episode: int) -> list[float] | None:
        """The stored laps of an episode's clock, exactly as its run read them (None: none stored)."""
        if not self.has_traces():
            return None
        row = self.db.execute(
            "SELECT codec, n, laps FROM clock_traces WHERE run_key = ? AND episode = ?", (run_key, episode)
        ).fetchone()
        if row is None:
            return None
        try:
            return decode_laps(row[2], int(row[1]), row[0])
        except (ValueError, zlib.error) as e:
            raise ResultsDatabaseError(
                f"{self.path}: the clock trace of episode {episode} of run {run_key} cannot be read: {e}", BAD_INPUT
            ) from None

    @_guarded
    def starts(self, world_key: str) -> dict[int, dict]:
        """The stored starts of ``world_key`` (:func:`rmm_envs.starts.world_key`): episode ->
        ``{"seed", "fingerprint", "doomed" (True / False / None), "method", "seconds"}``; empty
        for a database from before starts were stored."""
        if not self._table_exists("starts"):
            return {}
        rows = self.db.execute(
            "SELECT episode, seed, fingerprint, doomed, method, seconds FROM starts WHERE world_key = ?", (world_key,)
        ).fetchall()
        return {
            int(e): {"seed": int(sd), "fingerprint": fp, "doomed": None if d is None else bool(d), "method": m,
                     "seconds": sec}
            for e, sd, fp, d, m, sec in rows
        }  # fmt: skip

    @_guarded
    def add_starts(self, world_key: str, starts: Sequence[tuple[int, int, str, bool | None, str, float]]) -> None:
        """Store ``(episode, seed, fingerprint, doomed, method, seconds)`` of ``world_key``'s starts
        (one transaction; a start stored already is kept: starts never change for a world)."""
        self._writable()
        with self.db:
            self.db.executemany(
                "INSERT OR IGNORE INTO starts (world_key, episode, seed, fingerprint, doomed, method, seconds) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                [(world_key, int(e), int(sd), fp, None if d is None else int(bool(d)), m, float(sec))
                 for e, sd, fp, d, m, sec in starts],
            )  # fmt: skip

    @_guarded
    def episodes(self, run_key: str, n: int | None = None) -> list[dict]:
        q = (
            "SELECT * FROM episodes WHERE run_key = ?"
            + (" AND episode < ?" if n is not None else "")
            + " ORDER BY episode"
        )
        cur = self.db.execute(q, (run_key, n) if n is not None else (run_key,))
        names = [d[0] for d in cur.description]
        return [dict(zip(names, r, strict=True)) for r in cur.fetchall()]  # a row has one value per column

    # invocations
    @_guarded
    def add_invocation(self, command: str, args: dict, run_keys: dict, episodes: int) -> int:
        """Record a ``command`` (``"run"``, ``"sweep"``: the table's ``kind`` column) as running; its id."""
        self._writable()
        now = time.time()
        cur = self.db.execute(
            "INSERT INTO invocations (created, kind, args, run_keys, episodes, status, pid, host, updated) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                now,
                command,
                json.dumps(args, sort_keys=True),
                json.dumps(run_keys),
                episodes,
                "running",
                os.getpid(),
                socket.gethostname(),
                now,
            ),
        )
        self.db.commit()
        if cur.lastrowid is None:  # sqlite3 sets it after every INSERT
            raise TypeError("SQLite reported no row id for the new invocation")
        return int(cur.lastrowid)

    @_guarded
    def finish_invocation(self, inv_id: int, status: str = "finished", message: str | None = None) -> None:
        self._writable()
        if status not in ("finished", "interrupted", "failed"):
            raise ValueError(f"invocation status must be finished, interrupted or failed, got {status!r}")
        self.db.execute(
            "UPDATE invocations SET status = ?, message = ?, updated = ? WHERE id = ?",
            (status, message, time.time(), inv_id),
        )
        self.db.commit()

    def _stale(self, status: str, pid, host) -> bool:
        return status == "running" and pid is not None and host == socket.gethostname() and not pid_alive(int(pid))

    @_guarded
    def mark_stale_invocations(self) -> int:
        """Mark ``running`` invocations whose process is gone from this host as ``interrupted``; returns how many."""
        self._writable()
        rows = self.db.execute("SELECT id, pid, host, status FROM invocations WHERE status = 'running'").fetchall()
        stale = [r for r in rows if self._stale(r[3], r[1], r[2])]
        for inv_id, pid, _, _ in stale:
            self.db.execute(
                "UPDATE invocations SET status = 'interrupted', message = ? WHERE id = ?",
                (f"its process {pid} ended without recording an end (killed)", inv_id),
            )
        self.db.commit()
        return len(stale)

    @_guarded
    def invocation(self, inv_id: int | None = None, command: str | None = None) -> dict:
        """One invocation (``inv_id``, else the newest of ``command``, stored as ``kind``); ``state`` is its
        status, or ``stale`` for a ``running`` one whose process is gone."""
        q = "SELECT id, created, kind, args, run_keys, episodes, status, pid, host, updated, message FROM invocations"
        params: tuple = ()
        if inv_id is not None:
            q += " WHERE id = ?"
            params = (inv_id,)
        elif command is not None:
            q += " WHERE kind = ?"
            params = (command,)
        q += " ORDER BY id DESC LIMIT 1"
        row = self.db.execute(q, params).fetchone()
        if row is None:
            what = (
                f"invocation {inv_id}"
                if inv_id is not None
                else _COMMAND_NAMES.get(command, f"{command or 'benchmark'} invocation")
            )
            raise LookupError(f"no {what} recorded in {self.path}")
        inv = {
            "id": row[0],
            "created": row[1],
            "kind": row[2],
            "args": json.loads(row[3]),
            "run_keys": json.loads(row[4]),
            "episodes": row[5],
            "status": row[6],
            "pid": row[7],
            "host": row[8],
            "updated": row[9],
            "message": row[10],
        }
        inv["state"] = "stale" if self._stale(inv["status"], inv["pid"], inv["host"]) else inv["status"]
        return inv
