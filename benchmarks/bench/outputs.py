"""The files that ``rmm-bench`` commands write for a user, and the rules that keep them from
destroying what a user already has.

Every file output of ``export``, ``compare``, ``report --html``, ``replay --video`` and ``merge``
goes through :func:`check_output` before any work is done and through :func:`write_output` (or
:func:`publish`) at the end:

* an output path that is a file the command reads (the results database, its ``-wal`` or
  ``-shm``, whatever the path is called or linked as), or any existing SQLite database, is
  refused in one line (exit 2) and the input is left as it was: a results database is never
  written over by a table, a page or a video;
* the output is written to a temporary file beside the target (so the final rename stays on
  one file system) and moved into place only when complete.  A target that did not exist when
  the command was checked is created with a no-clobber link (:func:`os.link` fails if the name
  appeared meanwhile): two commands writing one new file, such as two ``merge`` runs into one
  ``OUT``, never both report success; the second one is refused naming the file.  A target that
  existed (a previous export, say) is replaced, as a user who named it asked;
* the folders of a target are made as needed; an error names the target the user asked for,
  never the temporary file.
"""

from __future__ import annotations

import errno
import os
from collections.abc import Callable, Iterable
from pathlib import Path

__all__ = ["SQLITE_MAGIC", "OutputExists", "check_output", "is_sqlite", "publish", "temporary_beside", "write_output"]

#: The first 16 bytes of every SQLite 3 database file.
SQLITE_MAGIC = b"SQLite format 3\x00"


class OutputExists(ValueError):
    """The output appeared while the command ran (another command wrote it): nothing was replaced."""


def is_sqlite(path: str | Path) -> bool:
    """Whether ``path`` is a file that starts as a SQLite database does."""
    try:
        with open(path, "rb") as f:
            return f.read(16) == SQLITE_MAGIC
    except OSError:
        return False


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_output(path: str | Path, flag: str, reads: Iterable[str | Path] = ()) -> Path:
    """Refuse ``path`` as an output (``ValueError`` naming ``flag`` and the path) when it is a
    folder, a file the command reads (``reads``, with each database's ``-wal``, ``-shm`` and
    ``-journal``), or an existing SQLite database; otherwise return it."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{flag} {path}: it is a folder; expected a file name")
    for source in reads:
        source = Path(source)
        for companion in (source, *(Path(f"{source}{s}") for s in ("-wal", "-shm", "-journal"))):
            if path.exists() and companion.exists() and _same_file(path, companion):
                raise ValueError(
                    f"{flag} {path}: it is {companion}, which this command reads; writing there would destroy "
                    "it; choose another file (nothing was written)"
                )
            if not path.exists() and path.resolve() == companion.resolve():
                raise ValueError(f"{flag} {path}: it is a file this command reads; choose another file")
    if is_sqlite(path):
        raise ValueError(
            f"{flag} {path}: it is an SQLite database (a results.db?); rmm-bench never writes over one; choose "
            "another file (nothing was written)"
        )
    return path


def temporary_beside(path: Path) -> Path:
    """A fresh temporary name beside ``path`` (hidden, tagged with this process)."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


def publish(tmp: Path, target: Path, existed: bool) -> None:
    """Move the complete file ``tmp`` to ``target``: replacing it when it ``existed`` before the
    command started (and is still no SQLite database), otherwise only if the name is still free
    (:class:`OutputExists` when another command created it meanwhile).  ``tmp`` is gone after."""
    try:
        if existed:
            if is_sqlite(target):
                raise OutputExists(f"{target} became an SQLite database while this command ran; it is left as it is")
            os.replace(tmp, target)
            return
        try:
            os.link(tmp, target)  # atomic and never overwrites: fails if the name was taken meanwhile
        except FileExistsError:
            raise OutputExists(
                f"{target} appeared while this command ran (another command writing the same file?); it is left as "
                "it is and this command's output was discarded"
            ) from None
        except OSError as e:
            if e.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK):
                raise
            # a file system without hard links: the best that is left is an exclusive create
            fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
            os.close(fd)
            os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def write_output(path: str | Path, write: Callable[[Path], object], existed: bool | None = None) -> Path:
    """Write a file through ``write(tmp)`` into a temporary file beside ``path`` and move it into
    place with :func:`publish`; the folders of ``path`` are made first.  ``existed``: whether the
    target existed when the command checked it (default: now).  An ``OSError`` names ``path``."""
    path = Path(path)
    if existed is None:
        existed = path.exists()
    tmp = temporary_beside(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # some writers make private temporary files: the output gets the usual mode
        publish(tmp, path, existed)
    except OSError as e:
        raise OSError(e.errno, e.strerror or str(e), str(path)) from None
    finally:
        tmp.unlink(missing_ok=True)
    return path
