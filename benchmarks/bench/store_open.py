"""Opening a results database: the checks a file passes before it is used (foreign, newer,
damaged, read-only, full), the migrations applied when it is opened for writing, and the one-line
errors (see :mod:`rmm_bench.store`).  :class:`StoreConnection` is what
:class:`rmm_bench.store.ResultsStore` is built on."""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

import rmm_envs
from rmm_bench.store_schema import (  # noqa: F401
    _INVOCATION_COLUMNS,
    _LATER_EPISODE_FIELDS,
    MIGRATIONS,
    SCHEMA_VERSION,
    ResultsDatabaseError,
)
from rmm_envs.os_errors import BAD_INPUT, RUN_FAILED, describe_os_error, file_size_limit

__all__ = ["StoreConnection"]


class StoreConnection:
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

    def _table_exists(self, name: str) -> bool:
        return (
            self.db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)).fetchone()
            is not None
        )
