"""Reference results shipped with the package: the fixed-clock Table I of every built-in system.

Offers :func:`reference_dbs` and :data:`REFERENCE_ENV` (the environment variable that points it
elsewhere).

Each ``*.db`` file in this folder is an ``rmm-bench`` results database (``results.db`` of a
fixed-clock run, trimmed of what a comparison does not read), so ``rmm-bench compare DIR
--reference`` pairs a user's own guardian with the stored guardians and baselines on the same
episodes without running them.  ``docs/comparing.md`` lists what is shipped, the commands that
made each file and how to regenerate them (``python -m benchmarks.make_reference``).
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["REFERENCE_ENV", "reference_dbs"]

#: an environment variable naming another folder of reference databases (used instead of this one)
REFERENCE_ENV = "RMM_REFERENCE_DIR"


def reference_dbs(folder: str | Path | None = None) -> list[Path]:
    """The reference databases: the ``*.db`` files of ``folder``, else of the folder named by
    :data:`REFERENCE_ENV`, else of this package folder, sorted by name."""
    if folder is None:
        folder = os.environ.get(REFERENCE_ENV) or Path(__file__).parent
    path = Path(folder)
    if not path.is_dir():
        raise ValueError(f"reference results folder {path} is not a directory (set by {REFERENCE_ENV} or an argument)")
    return sorted(path.glob("*.db"))
