"""How the commands report a failure of the machine rather than of the code: one line and an exit status.

Exit statuses, the same for ``rmm-bench`` and ``rmm-datagen``:

* :data:`BAD_INPUT` (2): the command asked for something that cannot be done as given: an
  output path that is a file, a directory the user cannot write, a read-only file system,
  a damaged results database.  Change the command (or the path) and run it again.
* :data:`RUN_FAILED` (1): the command was fine but could not finish: the disk is full, a
  file reached the size limit (``ulimit -f``), an I/O error, a cluster that cannot be reached.
  Everything stored so far is kept; fix the cause and rerun the same command.

:func:`describe_os_error` turns an :class:`OSError` into that line and status; nothing here
ever suggests deleting or moving what a user produced.
"""

from __future__ import annotations

import errno
import os
import resource

__all__ = ["BAD_INPUT", "RUN_FAILED", "describe_os_error", "file_size_limit"]

BAD_INPUT = 2
RUN_FAILED = 1

_KEPT = "what is stored is kept: rerun the same command"


def file_size_limit() -> int | None:
    """This process's file-size limit in bytes (``ulimit -f``), or None when there is none."""
    soft, _ = resource.getrlimit(resource.RLIMIT_FSIZE)
    return None if soft == resource.RLIM_INFINITY else int(soft)


def describe_os_error(e: OSError, path: str | os.PathLike | None = None) -> tuple[str, int]:
    """``(one line naming the path and what to do, exit status)`` for ``e``; ``path`` is named
    when the error carries no file name."""
    where = e.filename if getattr(e, "filename", None) else path
    name = f"{where}" if where is not None else "a file"
    reason = e.strerror or str(e) or type(e).__name__
    if isinstance(e, BrokenPipeError):  # `| head`: the reader of the output stopped early
        return (
            f"{reason}: the output was closed before the command finished writing it (a reader such as `| head` "
            f"that stops early); {_KEPT}",
            RUN_FAILED,
        )
    if isinstance(e, ConnectionError) and not e.filename:
        return (
            f"{reason}; check the address (--ray-address) or leave it out to start a local Ray, then {_KEPT}",
            RUN_FAILED,
        )
    if e.errno in (errno.ENOSPC, errno.EDQUOT):
        return f"no space left to write {name} ({reason}); free disk space (or quota), then {_KEPT}", RUN_FAILED
    if e.errno == errno.EFBIG:
        limit = file_size_limit()
        shown = f" (ulimit -f: {limit} bytes)" if limit is not None else ""
        return (f"{name} reached the file-size limit{shown}; raise it (ulimit -f unlimited), then {_KEPT}", RUN_FAILED)
    if e.errno in (errno.EACCES, errno.EPERM):
        return f"cannot write {name}: permission denied; make it writable or choose another --out", BAD_INPUT
    if e.errno == errno.EROFS:
        return f"cannot write {name}: the file system is read-only; choose another --out", BAD_INPUT
    if e.errno == errno.EEXIST:
        return f"{name} is a file, not a directory ({reason}); choose another --out", BAD_INPUT
    if e.errno == errno.ENOTDIR:
        return f"{name}: a part of this path is a file, not a directory ({reason}); choose another --out", BAD_INPUT
    if e.errno == errno.EIO:
        return f"I/O error writing {name} ({reason}); check the disk, then {_KEPT}", RUN_FAILED
    return f"{name}: {type(e).__name__}: {reason}", RUN_FAILED
