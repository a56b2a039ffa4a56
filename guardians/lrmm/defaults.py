"""Where the ``lrmm`` guardian's decision defaults come from: one precedence, written once.

The threshold (and the other decision defaults: commit, action, hand-back) is taken from the
first of these that states it:

1. the guardian's argument (``threshold=...``, ``--agent-opt lrmm.threshold=...``);
2. the model file's ``meta["decision"]`` (stored with how it was chosen,
   ``python -m rmm_guardians.lrmm.decision``);
3. the env's entry in :data:`rmm_guardians.lrmm.shipped.SHIPPED` (``decision``), only when the
   guardian uses that entry's shipped model (a model given by path has no shipped decision);
4. the paper's :data:`PAPER_THRESHOLD` (0.85) for the threshold (the guardian warns when it falls back to it).

:func:`stored_decision` picks the decision of 2-3, :func:`decision_threshold` applies 1-4.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PAPER_THRESHOLD", "check_threshold", "decision_threshold", "stored_decision"]

PAPER_THRESHOLD = 0.85  # the paper's Table I setting


def check_threshold(threshold, where: str = "threshold") -> float | None:
    """``threshold`` as a float in ``[0, 1]`` (``None`` passes: not given); a ``ValueError``
    naming ``where`` and the value otherwise."""
    if threshold is None:
        return None
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float, np.number)):
        raise ValueError(f"{where} must be a number in [0, 1], got {threshold!r}")
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"{where} must be in [0, 1], got {threshold}")
    return float(threshold)


def stored_decision(meta: dict, ship, model_given: bool) -> dict | None:
    """The decision defaults stored for the guardian's model: the model file's
    ``meta["decision"]``, else the shipped entry's ``ship.decision`` when the model is that
    entry's (``model_given`` False), else ``None``."""
    return meta.get("decision") or (ship.decision if ship is not None and not model_given else None)


def decision_threshold(threshold, decision: dict | None, where: str) -> tuple[float, str]:
    """The threshold by the module's precedence and where it came from (``"argument"``,
    ``"stored decision"`` or ``"paper"``: the caller warns, naming the model, in that case).
    ``decision``: :func:`stored_decision`'s; ``where`` names the model in messages."""
    given = check_threshold(threshold)
    if given is not None:
        return given, "argument"
    if decision is not None and "threshold" in decision:
        stored = float(decision["threshold"])
        if not 0.0 <= stored <= 1.0:
            raise ValueError(f"{where}: stored decision threshold must be in [0, 1], got {stored}")
        return stored, "stored decision"
    return PAPER_THRESHOLD, "paper"
