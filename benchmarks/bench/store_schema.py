"""The results database's layout: the episodes' columns, the schema versions and their
migrations, the clock traces' codec, and the one-line error a file that cannot be used gives
(see :mod:`rmm_bench.store`)."""

from __future__ import annotations

import functools
import os
import sqlite3
import typing
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rmm_bench.config import EpisodeResult
from rmm_envs.os_errors import BAD_INPUT

__all__ = [
    "EPISODE_FIELDS",
    "MIGRATIONS",
    "RETRIED_ERRORS",
    "SCHEMA_VERSION",
    "TRACE_CODEC",
    "ResultsDatabaseError",
    "decode_laps",
    "encode_laps",
    "guarded",
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

# the error_kind values that are failures of the run rather than results: every rerun retries them
RETRIED_ERRORS = ("timeout", "lost_worker", "input_changed", "env")

# what an invocation of each command (stored in the invocations table's kind) is called in messages
# (any other, or none: "... invocation")
_COMMAND_NAMES: dict[str | None, str] = {"run": "benchmark run", "sweep": "latency sweep"}

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
    for name, sql_type in _INVOCATION_COLUMNS.items():
        if name not in have:
            db.execute(f"ALTER TABLE invocations ADD COLUMN {name} {sql_type}")
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


def guarded(method):
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
