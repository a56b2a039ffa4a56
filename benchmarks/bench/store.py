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

import functools
import json
import os
import socket
import sqlite3
import time
import typing
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rmm_bench.config import EpisodeResult
from rmm_envs.os_errors import BAD_INPUT, RUN_FAILED, describe_os_error, file_size_limit

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


def _column(annotation) -> str:
    """The SQL column of an :class:`EpisodeResult` field's type: ``X`` -> ``... NOT NULL``,
    ``X | None`` -> nullable (``str`` TEXT, ``int`` INTEGER, ``float`` REAL)."""
    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    sql = {str: "TEXT", int: "INTEGER", float: "REAL"}[args[0] if args else annotation]
    return sql if args else f"{sql} NOT NULL"


#: The ``episodes`` table's columns, in order: :class:`EpisodeResult`'s fields (its owner).
EPISODE_FIELDS = {name: _column(tp) for name, tp in typing.get_type_hints(EpisodeResult).items()}

#: columns of ``episodes`` added by a later migration than version 1, with the version that adds each
_LATER_EPISODE_FIELDS = {"start": 3}
# the episodes table as version 1 creates it (a later migration adding a column adds it itself)
_V1_EPISODE_FIELDS = {k: v for k, v in EPISODE_FIELDS.items() if k not in _LATER_EPISODE_FIELDS}

# error kinds that are failures of the run rather than results: every rerun retries them
RETRIED_ERRORS = ("timeout", "lost_worker", "input_changed", "env")

# what an invocation of each kind is called in messages (any other kind, or none: "... invocation")
_INVOCATION_KINDS: dict[str | None, str] = {"run": "benchmark run", "sweep": "latency sweep"}

_INVOCATION_COLUMNS = {"pid": "INTEGER", "host": "TEXT", "updated": "REAL", "message": "TEXT"}


#: How ``clock_traces.laps`` holds the values (see the module docstring).
TRACE_CODEC = "f8le-shuffle-zlib"


def encode_laps(laps: Sequence[float]) -> bytes:
    """A clock trace as stored: the float64 values, little-endian, byte-shuffled, zlib-compressed
    (:data:`TRACE_CODEC`); :func:`decode_laps` returns exactly the same floats."""
    raw = np.asarray(laps, dtype="<f8").view(np.uint8).reshape(-1, 8)
    return zlib.compress(np.ascontiguousarray(raw.T).tobytes(), 6)


def decode_laps(blob: bytes, n: int, codec: str = TRACE_CODEC) -> list[float]:
    """The ``n`` laps of a stored trace (ValueError naming the codec or the count when they do not fit)."""
    if codec != TRACE_CODEC:
        raise ValueError(f"clock trace codec {codec!r} is not known to this version (expected {TRACE_CODEC!r})")
    raw = np.frombuffer(zlib.decompress(blob), dtype=np.uint8)
    if raw.size != 8 * n:
        raise ValueError(f"clock trace holds {raw.size} bytes, expected {8 * n} for {n} laps")
    return np.ascontiguousarray(raw.reshape(8, n).T).view("<f8").reshape(-1).tolist()


def _legacy_layout(db: sqlite3.Connection) -> None:
    """Version 0 -> 1: the tables, created if missing, and the columns added by probing before
    versions existed (error kinds, invocation bookkeeping, the safety cost)."""
    cols = ", ".join(f"{k} {v}" for k, v in _V1_EPISODE_FIELDS.items())
    for statement in (
        """CREATE TABLE IF NOT EXISTS runs (run_key TEXT PRIMARY KEY, agent TEXT NOT NULL, created REAL,
            config TEXT NOT NULL, provenance TEXT NOT NULL)""",
        f"CREATE TABLE IF NOT EXISTS episodes ({cols}, PRIMARY KEY (run_key, episode))",
        """CREATE TABLE IF NOT EXISTS invocations (id INTEGER PRIMARY KEY AUTOINCREMENT, created REAL,
            kind TEXT, args TEXT, run_keys TEXT, episodes INTEGER, status TEXT)""",
    ):
        db.execute(statement)
    have = {r[1] for r in db.execute("PRAGMA table_info(episodes)")}
    if "error_kind" not in have:
        db.execute("ALTER TABLE episodes ADD COLUMN error_kind TEXT")
        db.execute(
            "UPDATE episodes SET error_kind = CASE WHEN error LIKE 'EpisodeTimeout%' THEN 'timeout' "
            "ELSE 'guardian' END WHERE outcome = 'error'"
        )
    if "cost" not in have:  # databases written before the safety cost was stored
        db.execute("ALTER TABLE episodes ADD COLUMN cost REAL")
    have = {r[1] for r in db.execute("PRAGMA table_info(invocations)")}
    for name, kind in _INVOCATION_COLUMNS.items():
        if name not in have:
            db.execute(f"ALTER TABLE invocations ADD COLUMN {name} {kind}")
    db.execute("UPDATE invocations SET status = 'finished' WHERE status = 'done'")


def _clock_traces(db: sqlite3.Connection) -> None:
    """Version 1 -> 2: the ``clock_traces`` side table (see the module docstring)."""
    db.execute(
        "CREATE TABLE IF NOT EXISTS clock_traces (run_key TEXT NOT NULL, episode INTEGER NOT NULL, "
        "codec TEXT NOT NULL, n INTEGER NOT NULL, laps BLOB NOT NULL, PRIMARY KEY (run_key, episode))"
    )


def _starts(db: sqlite3.Connection) -> None:
    """Version 2 -> 3: each episode's start fingerprint (``episodes.start``) and the ``starts``
    table of doomed flags, one per world and episode (see the module docstring)."""
    have = {r[1] for r in db.execute("PRAGMA table_info(episodes)")}
    if "start" not in have:
        db.execute("ALTER TABLE episodes ADD COLUMN start TEXT")
    db.execute(
        "CREATE TABLE IF NOT EXISTS starts (world_key TEXT NOT NULL, episode INTEGER NOT NULL, seed INTEGER NOT NULL, "
        "fingerprint TEXT NOT NULL, doomed INTEGER, method TEXT NOT NULL, seconds REAL, "
        "PRIMARY KEY (world_key, episode))"
    )


def _parts(db: sqlite3.Connection) -> None:
    """Version 3 -> 4: the ``parts`` table, the provenance of each database ``rmm-bench merge``
    joined into this one (see the module docstring)."""
    db.execute(
        "CREATE TABLE IF NOT EXISTS parts (part INTEGER PRIMARY KEY, source TEXT NOT NULL, host TEXT, "
        "package_version TEXT, git_revision TEXT, argv TEXT, shard TEXT, started REAL, finished REAL, "
        "episodes INTEGER NOT NULL, run_keys TEXT NOT NULL, merged REAL NOT NULL)"
    )


#: The schema's migrations in order: entry ``i`` brings a database from version ``i`` to ``i + 1``.
#: Every later change of the layout is appended here (never edit a released one).
MIGRATIONS: tuple[tuple[str, Callable[[sqlite3.Connection], None]], ...] = (
    ("the layout of databases written before schema versions (columns added by probing)", _legacy_layout),
    ("clock_traces: the laps of a clocked episode's clock, for replay", _clock_traces),
    ("episodes.start and starts: each episode's start fingerprint and whether it was doomed", _starts),
    ("parts: the provenance of each database rmm-bench merge joined", _parts),
)
#: The newest schema version this code reads and writes.
SCHEMA_VERSION = len(MIGRATIONS)


def results_database(path: str | Path, command: str) -> Path:
    """The results database a command was given: ``path`` itself when it is a file, else
    ``path/results.db``; ``ValueError`` naming ``command`` and the path when there is none."""
    p = Path(path)
    if p.is_file():
        return p
    if not p.exists():
        raise ValueError(f"{command} {p}: it does not exist; expected the --out directory of an rmm-bench run")
    db = p / "results.db"
    if not db.is_file():
        raise ValueError(f"{command} {p}: it holds no results.db; expected the --out directory of an rmm-bench run")
    return db


class ResultsDatabaseError(RuntimeError):
    """``results.db`` cannot be used; ``status`` is the exit status (2: change the command or the
    file, 1: the run could not finish, rerun it)."""

    def __init__(self, message: str, status: int = BAD_INPUT) -> None:
        super().__init__(message)
        self.status = status


def _guarded(method):
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        try:
            return method(self, *args, **kwargs)
        except sqlite3.DatabaseError as e:
            raise self._error(e) from None

    return wrapper


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, another user's
        return True
    return True


class ResultsStore:
    """The results database at ``path``; ``read_only``: opened through a read-only URI, never
    migrated nor written (what ``rmm-bench replay`` uses).  ``version``: its schema version as
    found when opened (before any migration)."""

    def __init__(self, path: str | Path, read_only: bool = False) -> None:
        self.path = Path(path)
        self.read_only = read_only
        if read_only:
            if not self.path.is_file():
                what = "is a directory" if self.path.is_dir() else "does not exist"
                raise ResultsDatabaseError(f"{self.path} {what}: expected a results database (results.db)", BAD_INPUT)
        else:
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as e:
                raise ResultsDatabaseError(*describe_os_error(e, self.path.parent)) from None
        connection: sqlite3.Connection | None = None
        try:
            if read_only:
                self._refuse_foreign()
                self.db = connection = sqlite3.connect(self._read_only_uri(), uri=True, timeout=30)
            else:
                self.db = connection = sqlite3.connect(str(self.path), timeout=30)
            self.version = self._user_version()
            self._refuse_newer(self.version)
            if not read_only:
                self.db.execute("PRAGMA journal_mode=WAL")
                self.db.execute("PRAGMA synchronous=NORMAL")
            problems = [r[0] for r in self.db.execute("PRAGMA quick_check(5)")]
            if problems != ["ok"]:
                raise sqlite3.DatabaseError("; ".join(problems)[:300])
            if not read_only:
                self._migrate()
            else:
                self._refuse_without_tables()
        except sqlite3.DatabaseError as e:
            if connection is not None:
                connection.close()
            raise self._error(e) from None
        except ResultsDatabaseError:
            if connection is not None:
                connection.close()
            raise

    def _read_only_uri(self) -> str:
        """How a read-only command opens the file, leaving nothing beside it and working in a
        read-only folder.  A database in rollback-journal mode (every database a command has
        finished with: :meth:`close` leaves WAL mode) is opened ``mode=ro``, which creates no
        file.  A database still marked WAL (written by an older version, or a writer's) has to
        be read through a ``-shm`` file beside it, which SQLite creates and leaves behind, and
        cannot create in a read-only folder; when no ``-wal`` file is beside it, no writer has it
        open and every committed page is in the file itself, so it is opened ``immutable=1``
        (read as a plain file, no locks, nothing created).  With a ``-wal`` file beside it (a run
        in progress, or one killed), ``mode=ro`` reads the committed pages of both."""
        uri = self.path.resolve().as_uri()
        wal_header = False
        try:
            with open(self.path, "rb") as f:
                header = f.read(20)
            wal_header = len(header) == 20 and header[18:20] == b"\x02\x02"  # file format versions: 2 = WAL
        except OSError:
            pass
        if wal_header and not Path(f"{self.path}-wal").exists():
            return uri + "?immutable=1"
        return uri + "?mode=ro"

    def _refuse_foreign(self) -> None:
        """One line for an empty file, which SQLite would read as an empty database (a file that
        is not SQLite at all is told apart as damaged when it is opened: :meth:`_error`)."""
        try:
            size = self.path.stat().st_size
        except OSError:
            return  # sqlite3 names the cause
        if size == 0:
            raise ResultsDatabaseError(
                f"{self.path} is empty (0 bytes): it is not a results database (expected the results.db of an "
                "rmm-bench run)",
                BAD_INPUT,
            )

    def _refuse_without_tables(self) -> None:
        missing = [t for t in ("runs", "episodes") if not self._table_exists(t)]
        if missing:
            raise ResultsDatabaseError(
                f"{self.path} is an SQLite database but not a results database: it has no {' or '.join(missing)} "
                "table (expected the results.db of an rmm-bench run)",
                BAD_INPUT,
            )

    def _user_version(self) -> int:
        return int(self.db.execute("PRAGMA user_version").fetchone()[0])

    def _refuse_newer(self, version: int) -> None:
        if version > SCHEMA_VERSION:
            import rmm_envs

            raise ResultsDatabaseError(
                f"{self.path} has results-store schema version {version}, newer than this rmm-bench "
                f"({rmm_envs.__version__}) knows (versions up to {SCHEMA_VERSION}); open it with the newer "
                f"rmm-bench that wrote it, or upgrade",
                BAD_INPUT,
            )

    def _migrate(self) -> None:
        """Apply the missing :data:`MIGRATIONS` in one transaction (the version re-read inside it,
        so two commands opening one old file migrate it once)."""
        if self.version == SCHEMA_VERSION:
            return
        self.db.execute("BEGIN IMMEDIATE")
        try:
            version = self._user_version()
            self._refuse_newer(version)
            for _, migration in MIGRATIONS[version:]:
                migration(self.db)
            self.db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            self.db.commit()
        except BaseException:
            self.db.rollback()
            raise

    def _writable(self) -> None:
        if self.read_only:
            raise ResultsDatabaseError(f"{self.path} was opened read-only: nothing is written to it", BAD_INPUT)

    def _intact(self) -> bool:
        """Whether the file passes SQLite's integrity check, read through a separate read-only connection."""
        try:
            con = sqlite3.connect(self.path.resolve().as_uri() + "?mode=ro", uri=True, timeout=5)
            try:
                return [r[0] for r in con.execute("PRAGMA integrity_check(1)")] == ["ok"]
            finally:
                con.close()
        except (sqlite3.Error, OSError):
            return False

    def _at_size_limit(self) -> bool:
        limit = file_size_limit()
        if limit is None:
            return False
        sizes = [
            f.stat().st_size for f in (self.path, Path(f"{self.path}-wal"), Path(f"{self.path}-journal")) if f.exists()
        ]
        return max(sizes, default=0) + (1 << 20) >= limit

    def _disk_full(self) -> bool:
        import shutil

        try:
            return shutil.disk_usage(self.path.parent).free < (1 << 20)
        except OSError:
            return False

    def _error(self, e: sqlite3.DatabaseError) -> ResultsDatabaseError:
        """One line for a SQLite error on this file, the cause told apart (see the module docstring)."""
        text = str(e).replace("\n", " ")
        name = getattr(e, "sqlite_errorname", "") or ""
        path = self.path
        kept = "the stored episodes are kept: rerun the same command"
        if name.startswith("SQLITE_READONLY") or "readonly" in text:
            return ResultsDatabaseError(
                f"cannot write {path} ({text}): the file, its directory (which holds its -wal and -shm "
                f"files) or its file system is read-only for this user; make them writable or choose "
                f"another --out; the database is intact",
                BAD_INPUT,
            )
        if self.read_only and Path(f"{path}-wal").exists() and not os.access(path.parent, os.W_OK):
            return ResultsDatabaseError(
                f"cannot read {path} ({text}): a {path.name}-wal file beside it holds episodes not yet in the file "
                "itself (a run still writing, or killed), and SQLite must create its -shm file beside them to read "
                "both, which this read-only folder refuses; copy the folder somewhere writable and read the copy",
                BAD_INPUT,
            )
        if name.startswith("SQLITE_CANTOPEN") or "unable to open" in text:
            what = "is a directory" if path.is_dir() else "cannot be created or opened in its directory (not writable?)"
            return ResultsDatabaseError(f"cannot open {path} ({text}): it {what}; choose another --out", BAD_INPUT)
        if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")) or "locked" in text or "busy" in text:
            return ResultsDatabaseError(
                f"{path} is locked by another process ({text}); wait for the other rmm-bench "
                "command to finish, or use another --out; the database is intact",
                RUN_FAILED,
            )
        if name == "SQLITE_FULL" or "full" in text:
            return ResultsDatabaseError(
                f"cannot write {path} ({text}): the disk is full; free disk space, then {kept}", RUN_FAILED
            )
        damaged = (
            name.startswith(("SQLITE_NOTADB", "SQLITE_CORRUPT")) or "not a database" in text or "malformed" in text
        )
        if not damaged and (name.startswith("SQLITE_IOERR") or "I/O error" in text):
            if self._at_size_limit():
                return ResultsDatabaseError(
                    f"cannot write {path} ({text}): it reached the file-size limit (ulimit -f: "
                    f"{file_size_limit()} bytes); raise the limit (ulimit -f unlimited), then {kept}",
                    RUN_FAILED,
                )
            if self._disk_full():
                return ResultsDatabaseError(
                    f"cannot write {path} ({text}): the disk is full; free disk space, then {kept}", RUN_FAILED
                )
        if not damaged and self._intact():
            return ResultsDatabaseError(
                f"cannot use {path} ({text}), though its integrity check passes: the stored "
                f"episodes are intact; check the disk and the file's permissions, then rerun the "
                f"same command",
                RUN_FAILED,
            )
        return ResultsDatabaseError(
            f"{path} is damaged or not a results database ({text}); rmm-bench cannot read the episodes it holds. Export "
            f"what is still readable first (sqlite3 {path} .recover > {path}.sql, with the sqlite3 shell), then move it "
            f"aside (mv {path} {path}.damaged) and rerun: the run starts afresh in a new database, and the episodes of "
            f"the old one are lost to rmm-bench",
            BAD_INPUT,
        )

    def close(self) -> None:
        """Close the file; a writer also takes it out of WAL mode when it is the last one using it,
        so the finished database is one self-contained file that read-only commands open without
        creating ``-wal``/``-shm`` files beside it, in any folder (:meth:`_read_only_uri`)."""
        if not self.read_only:
            try:
                self.db.execute("PRAGMA busy_timeout = 0")  # another command has it open: leave WAL as it is
                self.db.execute("PRAGMA journal_mode=DELETE")
            except sqlite3.Error:
                pass
        self.db.close()

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

    def _table_exists(self, name: str) -> bool:
        return (
            self.db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)).fetchone()
            is not None
        )

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
    def add_invocation(self, kind: str, args: dict, run_keys: dict, episodes: int) -> int:
        self._writable()
        now = time.time()
        cur = self.db.execute(
            "INSERT INTO invocations (created, kind, args, run_keys, episodes, status, pid, host, updated) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (
                now,
                kind,
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
    def invocation(self, inv_id: int | None = None, kind: str | None = None) -> dict:
        """One invocation; ``state`` is its status, or ``stale`` for a ``running`` one whose process is gone."""
        q = "SELECT id, created, kind, args, run_keys, episodes, status, pid, host, updated, message FROM invocations"
        params: tuple = ()
        if inv_id is not None:
            q += " WHERE id = ?"
            params = (inv_id,)
        elif kind is not None:
            q += " WHERE kind = ?"
            params = (kind,)
        q += " ORDER BY id DESC LIMIT 1"
        row = self.db.execute(q, params).fetchone()
        if row is None:
            what = (
                f"invocation {inv_id}"
                if inv_id is not None
                else _INVOCATION_KINDS.get(kind, f"{kind or 'benchmark'} invocation")
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
