"""Reference results shipped with the package: the fixed-clock Table I of every built-in system.

Offers :func:`reference_dbs`; ``RMM_REFERENCE_DIR`` (:mod:`rmm_envs.environment_variables`) points it elsewhere.

Each ``*.db`` file in this folder is an ``rmm-bench`` results database (``results.db`` of a
fixed-clock run, trimmed of what a comparison does not read), so ``rmm-bench compare DIR
--reference`` pairs a user's own guardian with the stored guardians and baselines on the same
episodes without running them.  ``docs/comparing.md`` lists what is shipped, the commands that
made each file and how to regenerate them (``python -m benchmarks.make_reference``).
"""

from __future__ import annotations

from pathlib import Path

from rmm_envs.environment_variables import REFERENCE_DIR, reference_dir

__all__ = ["reference_dbs"]


def reference_dbs(folder: str | Path | None = None) -> list[Path]:
    """The reference databases: the ``*.db`` files of ``folder``, else of the folder named by
    ``$RMM_REFERENCE_DIR``, else of this package folder, sorted by name."""
    path = Path(folder) if folder is not None else (reference_dir() or Path(__file__).parent)
    if not path.is_dir():
        raise ValueError(f"reference results folder {path} is not a directory (set by {REFERENCE_DIR} or an argument)")
    return sorted(path.glob("*.db"))
