"""The package's default system, named once: the paper's case study, Dubins4D among circles.

The env ids the commands run when no ``--env`` is given (``rmm-bench``, ``rmm-demo``, the
ablation) and the env ``rmm-datagen`` labels by default; the paper's Table I describes this
system alone.
"""

from __future__ import annotations

__all__ = ["DEFAULT_ENV", "DEFAULT_LABELLED_ENV", "PAPER_SYSTEM"]

#: The paper's case study and this package's default system (its name in the table of systems)
PAPER_SYSTEM = "Dubins4D"
#: The env a benchmark runs by default: the default system under parallel autonomy, non-blocking
DEFAULT_ENV = f"{PAPER_SYSTEM}Parallel-v0"
#: The env labelled and modelled by default: the default system's blocking guarded env
DEFAULT_LABELLED_ENV = f"{PAPER_SYSTEM}Guarded-v0"
