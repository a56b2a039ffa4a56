"""The ``lrmm`` guardian's settings, its named presets, and where each default comes from.

:class:`LRMMSettings` holds the threshold, the strategies (:mod:`rmm_guardians.lrmm.strategies`)
and the observation field the model reads; :data:`LRMM_PRESETS` names ``lrmm`` (everything from
the model), ``lrmm-paper`` (the paper's rule) and ``core`` (the learned risk and the env's safe
default, nothing else).  Each of the threshold and the strategies comes from the first of: the
guardian's argument; the model file's ``meta["decision"]`` (``{"threshold", "strategies",
"chosen_by"}``, written by ``python -m rmm_guardians.lrmm.decision``); the system table's entry
(:data:`rmm_guardians.lrmm.shipped.SHIPPED`, only for that entry's own model); else the paper's
threshold :data:`PAPER_THRESHOLD` (with a warning) and no strategies.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rmm_guardians._checks import Settings
from rmm_guardians.lrmm.strategies import BrakeTurn, Strategy, parse_strategies
from rmm_guardians.lrmm.strategies.spec import parse_item, spec_items

__all__ = [
    "DECISION_KEYS",
    "LRMM_PRESETS",
    "PAPER_THRESHOLD",
    "LRMMSettings",
    "check_threshold",
    "decision_threshold",
    "stored_decision",
    "stored_strategies",
]

PAPER_THRESHOLD = 0.85  # the paper's Table I setting
#: what a model file's ``meta["decision"]`` may hold
DECISION_KEYS = ("threshold", "strategies", "chosen_by")


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


@dataclass(frozen=True)
class LRMMSettings(Settings):
    """The ``lrmm`` guardian's settings, checked at construction.

    ``threshold``: in control while the risk is strictly above it (``None``: the stored one).
    ``strategies``: :class:`~rmm_guardians.lrmm.strategies.Strategy` objects or a spec string
    (:func:`~rmm_guardians.lrmm.strategies.parse_strategies`; ``""``: none, the core alone;
    ``None``: the stored ones; items starting with ``-``/``+`` edit the stored ones).
    ``inputs``: the observation field the model reads (``None``: the system table's, else the
    whole observation)."""

    threshold: float | None = None
    strategies: Any = None
    inputs: str | None = None

    def __post_init__(self) -> None:
        self._set("threshold", check_threshold(self.threshold))
        if self.inputs is not None and not isinstance(self.inputs, str):
            raise ValueError(f"inputs must be an observation field name (str) or None, got {self.inputs!r}")
        s = self.strategies
        if s is None:
            return
        if not isinstance(s, (str, list, tuple)):
            raise ValueError(f"strategies must be a spec string, a sequence of Strategy objects or None, got {s!r}")
        items, edits = spec_items(s)
        if edits:  # edits of the stored ones: checked here, applied once the model is known
            for i in items:
                parse_item(i[1:].strip())
            self._set("strategies", tuple(items))
        else:
            self._set("strategies", parse_strategies(items))

    def replace(self, **changes: Any) -> LRMMSettings:
        """These settings with ``changes``; edits (``"-Commit"``) of settings that name their own
        strategies (a preset's, e.g. ``lrmm-paper``'s ``BrakeTurn``) edit those, not the model's."""
        edit = changes.get("strategies")
        own = isinstance(self.strategies, tuple) and not any(isinstance(i, str) for i in self.strategies)
        if own and isinstance(edit, (str, list, tuple)) and spec_items(edit)[1]:
            changes = {**changes, "strategies": parse_strategies(edit, self.strategies)}
        return super().replace(**changes)

    def resolve(self, stored: tuple[Strategy, ...]) -> tuple[Strategy, ...]:
        """The strategies these settings give, ``stored`` being the model's (fresh copies)."""
        if self.strategies is None:
            out = stored
        elif any(isinstance(i, str) for i in self.strategies):
            out = parse_strategies(list(self.strategies), stored)
        else:
            out = self.strategies
        return tuple(s.clone() for s in out)


#: The named settings: ``LRMMSettings.preset("lrmm-paper", threshold=0.5)``.
LRMM_PRESETS = {
    "lrmm": LRMMSettings(),
    "lrmm-paper": LRMMSettings(threshold=PAPER_THRESHOLD, strategies=(BrakeTurn(),)),
    "core": LRMMSettings(strategies=()),
}
LRMMSettings.PRESETS = LRMM_PRESETS


def stored_decision(meta: dict, ship, model_given: bool) -> dict | None:
    """The decision stored for the guardian's model: the model file's ``meta["decision"]``, else
    the system table's ``ship.decision`` when the model is that entry's (``model_given`` False),
    else ``None``."""
    return meta.get("decision") or (ship.decision if ship is not None and not model_given else None)


def stored_strategies(decision: dict | None, where: str) -> tuple[Strategy, ...]:
    """The strategies a stored decision names (none without one); a ``ValueError`` naming
    ``where`` (the model) for a key or strategy this version does not know."""
    if not decision:
        return ()
    unknown = sorted(set(decision) - set(DECISION_KEYS))
    if unknown:
        raise ValueError(
            f"{where}: stored decision has unknown key(s) {unknown}; a decision holds {', '.join(DECISION_KEYS)} "
            "(rewrite it with python -m rmm_guardians.lrmm.decision)"
        )
    specs = decision.get("strategies", [])
    if not isinstance(specs, list) or not all(isinstance(x, str) for x in specs):
        raise ValueError(f"{where}: stored decision strategies must be a list of spec strings, got {specs!r}")
    try:
        return parse_strategies(specs)
    except ValueError as e:
        raise ValueError(f"{where}: stored decision: {e}") from None


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
