"""OSQP's solves without its unasked-for output: :func:`quietly`.

OSQP 1.x prints "Polishing not needed - no active set detected at optimal point" to Python's
``sys.stdout`` (``PySys_WriteStdout``) after every polished solution that has no active row,
whatever its ``verbose`` setting.  In a benchmark that is thousands of lines mixed into the
table the command prints.  The CBF guardians' solves go through :func:`quietly`.
"""

from __future__ import annotations

import sys

__all__ = ["quietly"]


class _Discard:
    """A text stream that keeps nothing."""

    def write(self, text: str) -> int:
        return len(text)

    def flush(self) -> None:
        pass


_DISCARD = _Discard()


def quietly(solve, *args, **kwargs):
    """``solve(*args, **kwargs)`` with ``sys.stdout`` discarding what is written to it, and put
    back after (also when the solve raises).  Anything another thread prints while the solve
    runs is dropped too; the solve's outcome is in its status, which the callers check."""
    saved = sys.stdout
    sys.stdout = _DISCARD
    try:
        return solve(*args, **kwargs)
    finally:
        sys.stdout = saved
