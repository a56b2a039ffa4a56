"""The ``lrmm`` guardian's settings, its named presets, and where each default comes from.

:class:`LRMMSettings` holds the threshold, the strategies (:mod:`rmm_guardians.lrmm.strategies`)
and the observation field the model reads; :data:`LRMM_PRESETS` names ``lrmm`` (everything from
the model's decision), ``lrmm-paper`` (the paper's rule) and ``core`` (the learned risk and the
env's safe default, nothing else).  Each of the threshold and the strategies comes from the
guardian's argument, else from the model's decision: the text file beside the model file
(:mod:`rmm_guardians.lrmm.decision`, written by ``rmm-bench tune``), its one source.  ``lrmm``
refuses a model without one unless given a threshold (then no strategies unless given);
``lrmm-paper`` reads no decision (the paper's threshold :data:`PAPER_THRESHOLD` unless given).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from rmm_guardians._checks import Settings
from rmm_guardians.lrmm.strategies import BrakeTurn, Strategy, parse_strategies
from rmm_guardians.lrmm.strategies.spec import parse_item, spec_items

__all__ = [
    "LRMM_PRESETS",
    "PAPER_THRESHOLD",
    "LRMMSettings",
    "check_threshold",
]

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


@dataclass(frozen=True)
class LRMMSettings(Settings):
    """The ``lrmm`` guardian's settings, checked at construction.

    ``threshold``: in control while the risk is strictly above it (``None``: the decision's).
    ``strategies``: :class:`~rmm_guardians.lrmm.strategies.Strategy` objects or a spec string
    (:func:`~rmm_guardians.lrmm.strategies.parse_strategies`; ``""``: none, the core alone;
    ``None``: the decision's; items starting with ``-``/``+`` edit the decision's).
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

    def needs_decision(self) -> bool:
        """Whether these settings leave the threshold or the strategies (or edits of them) to the
        model's decision."""
        return self.threshold is None or self.strategies is None or any(isinstance(i, str) for i in self.strategies)

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
