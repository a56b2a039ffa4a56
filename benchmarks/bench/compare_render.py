"""``rmm-bench compare``'s Markdown: the tables of a :class:`rmm_bench.compare.Comparison`.

Agent names come from the database and may hold anything: every one is written through
:func:`rmm_bench.names.md_cell`, so a ``|`` never shifts a column.
"""

from __future__ import annotations

import math

from rmm_bench.names import md_cell

__all__ = ["continuous_table", "episodes_cell", "p_text", "pairs_table", "pct"]


def pct(v: float) -> str:
    """A fraction in %, one decimal; ``—`` when missing."""
    return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{100 * v:.1f}"


def p_text(v: float) -> str:
    """A p-value, 3 significant digits (scientific below 1e-4); ``—`` when there is no test."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.3g}" if v >= 1e-4 else f"{v:.2e}"


def episodes_cell(eps: list[int], total: int, show: int) -> str:
    """The first ``show`` episode numbers, and how many more."""
    if not eps:
        return ""
    more = f" (+{total - len(eps[:show])})" if total > show else ""
    return ",".join(map(str, eps[:show])) + more


def _diff(r) -> str:
    if isinstance(r.diff, float) and math.isnan(r.diff) and math.isnan(r.lo):
        return "—"  # no interval (the error row)
    return f"{pct(r.diff)} [{pct(r.lo)}, {pct(r.hi)}]"


def pairs_table(pairs, paired: bool, show: int) -> str:
    """The outcome rows of every pair."""
    if paired:
        head = (
            "| A | B | outcome | episodes | A [%] | B [%] | A - B [%] (95%) | A only | B only | both | "
            "McNemar p | A-only episodes | B-only episodes |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|"
        )
        lines = [head]
        for r in pairs.itertuples():
            lines.append(
                f"| {md_cell(r.a)} | {md_cell(r.b)} | {r.outcome} | {r.n} | {pct(r.rate_a)} | {pct(r.rate_b)} | "
                f"{_diff(r)} | {r.a_only} | {r.b_only} | {r.both} | "
                f"{p_text(r.p_value)} | {episodes_cell(r.a_only_episodes, r.a_only, show)} | "
                f"{episodes_cell(r.b_only_episodes, r.b_only, show)} |"
            )
        return "\n".join(lines) + "\n"
    lines = [
        "| A | B | outcome | A episodes | B episodes | A [%] | B [%] | A - B [%] (95%, unpaired) |\n"
        "|---|---|---|---|---|---|---|---|"
    ]
    for r in pairs.itertuples():
        lines.append(
            f"| {md_cell(r.a)} | {md_cell(r.b)} | {r.outcome} | {r.n_a} | {r.n_b} | {pct(r.rate_a)} | "
            f"{pct(r.rate_b)} | {_diff(r)} |"
        )
    return "\n".join(lines) + "\n"


def _num(v: float, digits: int = 3) -> str:
    return "—" if math.isnan(v) else f"{v:.{digits}g}"


def continuous_table(cont, units: dict[str, str]) -> str:
    """The continuous rows of every pair (``units``: column -> its unit)."""
    lines = ["| A | B | column | episodes | A | B | A - B (95%) |", "|---|---|---|---|---|---|---|"]
    for r in cont.itertuples():
        lines.append(
            f"| {md_cell(r.a)} | {md_cell(r.b)} | {r.column} [{units[r.column]}] | {r.n} | {_num(r.mean_a)} | "
            f"{_num(r.mean_b)} | {_num(r.diff)} [{_num(r.lo)}, {_num(r.hi)}] |"
        )
    return "\n".join(lines) + "\n"
