"""Every pair of agents at once: the pairwise matrices and the summary the results page leads with.

Offers :func:`holm`, :data:`CORRECTION`, :data:`ALPHA`, :data:`OUTCOMES`, :class:`PairCell`,
:func:`pairwise_matrices`, :func:`cell_for` and :func:`summary`.

``rmm-bench compare`` tests each pair of agents on each outcome with the exact McNemar test
(:mod:`rmm_bench.paired`).  Nine agents make 36 pairs per outcome, and at 5% each some of 36
true-null tests would come out "significant" by chance; so the page calls a difference
significant when its p-value stays at or below 5% after Holm's step-down correction over the
pairs of that outcome, which keeps the chance of any false call among them at or below 5%
(the family-wise error rate) whatever the tests' dependence.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from rmm_bench.report_figures import rate_intervals, rates_order

__all__ = ["ALPHA", "CORRECTION", "OUTCOMES", "PairCell", "cell_for", "holm", "pairwise_matrices", "summary"]

#: the family-wise error rate the page's "significant" keeps
ALPHA = 0.05
#: the multiple-comparison correction, as the page names it
CORRECTION = "Holm–Bonferroni"
#: compare's outcomes the page shows a matrix of, in order: outcome -> (label, lower is better)
OUTCOMES = {
    "goal": ("Success", False),
    "collision": ("Collision", True),
    "avoidable collision": ("Collision, avoidable starts", True),
    "timeout": ("Timeout", True),
}


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm's step-down adjusted p-values (Holm 1979, Scand. J. Statist. 6, 65-70) of a family of
    tests, in the order given: with the ``m`` p-values sorted, ``p(1) <= ... <= p(m)``, the
    adjusted ``p~(i) = max over j <= i of min(1, (m - j + 1) p(j))``; a test is rejected at
    family-wise level ``alpha`` when ``p~ <= alpha``.  A NaN (no test) stays NaN and is not
    counted in ``m``."""
    values = [float(p) for p in p_values]
    tested = sorted((i for i, p in enumerate(values) if not math.isnan(p)), key=lambda i: values[i])
    m = len(tested)
    out = [math.nan] * len(values)
    running = 0.0
    for rank, i in enumerate(tested):
        running = max(running, min(1.0, (m - rank) * values[i]))
        out[i] = running
    return out


@dataclass(frozen=True)
class PairCell:
    """One pair's test on one outcome, as ``compare`` ordered it: ``diff = rate_a - rate_b``
    (fractions), its 95% interval, McNemar's ``p_value`` and ``p_holm`` over the outcome's pairs."""

    a: str
    b: str
    outcome: str
    n: int
    rate_a: float
    rate_b: float
    diff: float
    lo: float
    hi: float
    p_value: float
    p_holm: float

    @property
    def tested(self) -> bool:
        return not math.isnan(self.p_holm)

    @property
    def significant(self) -> bool:
        return self.tested and self.p_holm <= ALPHA

    def better(self) -> str | None:
        """The agent of the pair significantly better on this outcome (fewer collisions or timeouts,
        more successes), else None."""
        if not self.significant or self.diff == 0:
            return None
        lower = OUTCOMES[self.outcome][1]
        return self.a if (self.diff < 0) == lower else self.b


def pairwise_matrices(pairs) -> dict[str, dict[tuple[str, str], PairCell]]:
    """Outcome (of :data:`OUTCOMES`, those ``pairs`` holds) -> ``(a, b)`` -> :class:`PairCell`:
    ``pairs`` is :attr:`rmm_bench.compare.Comparison.pairs` (paired) of one group; each outcome's
    p-values are corrected together (:func:`holm`)."""
    out: dict[str, dict[tuple[str, str], PairCell]] = {}
    for outcome in OUTCOMES:
        rows = [r for r in pairs.itertuples() if r.outcome == outcome]
        if not rows:
            continue
        adjusted = holm([r.p_value for r in rows])
        out[outcome] = {
            (r.a, r.b): PairCell(r.a, r.b, outcome, int(r.n), r.rate_a, r.rate_b, r.diff, r.lo, r.hi, r.p_value, p)
            for r, p in zip(rows, adjusted, strict=True)
        }
    return out


def cell_for(matrix: dict[tuple[str, str], PairCell], x: str, y: str) -> tuple[float, PairCell] | None:
    """The difference ``x - y`` (a fraction) and the cell of the pair, in whichever order
    ``compare`` put it; None when the pair was not compared."""
    if (x, y) in matrix:
        return matrix[(x, y)].diff, matrix[(x, y)]
    if (y, x) in matrix:
        return -matrix[(y, x)].diff, matrix[(y, x)]
    return None


def _names(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def summary(rows: list[dict], matrices: dict[str, dict[tuple[str, str], PairCell]] | None) -> str:
    """One paragraph from the numbers: which agent collides least (its rate and 95% interval), which
    agents it collides significantly less than after the correction and which it does not, which
    reaches the goal most often, and how many pairs differ significantly on each outcome."""
    order = [rows[i] for i in rates_order(rows)]
    rates = {str(r["agent"]): rate_intervals(r) for r in order}
    ranked = [a for a in rates if "collision" in rates[a]]
    if not ranked:
        return "No agent has an episode with a result yet."
    least = ranked[0]
    p, lo, hi, n = rates[least]["collision"]
    text = [f"{least} collides least: {p:.1f}% of {n:,} episodes (95% interval {lo:.1f}–{hi:.1f}%)"]
    if "avoidable_collision" in rates[least]:
        pa, _, _, na = rates[least]["avoidable_collision"]
        text[-1] += f", {pa:.1f}% of the {na:,} avoidable starts"
    text[-1] += "."
    collision = (matrices or {}).get("collision")
    if collision:
        m = sum(c.tested for c in collision.values())
        below: list[str] = []
        alike: list[str] = []
        for other in ranked[1:]:
            found = cell_for(collision, least, other)
            if found is not None and found[1].tested:
                (below if found[1].better() == least else alike).append(other)
        said = []
        if below:
            said.append(f"significantly less than {_names(below)}")
        if alike:
            said.append(f"no differently from {_names(alike)}")
        if said:
            text.append(
                f"Paired episode by episode (exact McNemar test, {CORRECTION} over the {m} pairs, {ALPHA:.0%} "
                f"family-wise), it collides {' and '.join(said)}."
            )
    goals = [a for a in rates if "goal" in rates[a]]
    if goals:
        best = max(goals, key=lambda a: rates[a]["goal"][0])
        text.append(f"{best} reaches the goal most often ({rates[best]['goal'][0]:.1f}%).")
    if matrices:
        counts = []
        for outcome, matrix in matrices.items():
            tested = [c for c in matrix.values() if c.tested]
            sig = sum(c.significant for c in tested)
            counts.append(f"{'success' if outcome == 'goal' else outcome} {sig} of {len(tested)}")
        text.append(
            f"Pairs that differ significantly after the correction: {'; '.join(counts)}; "
            "the matrices below give each difference."
        )
    elif len(rows) > 1:
        text.append("No paired comparison: see below.")
    return " ".join(text)
