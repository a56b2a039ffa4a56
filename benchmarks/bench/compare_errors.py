"""Errored episodes in ``rmm-bench compare``: where a guardian raised, it has no outcome.

An episode whose guardian raised is stored with outcome ``error`` (kind ``guardian``; the kinds
with no result at all, :data:`rmm_bench.store.RETRIED_ERRORS`, are left out when read).  It is
neither a goal, a collision nor a timeout of that guardian, and counting it as "not a collision"
would credit a guardian that crashed with never colliding.  So a pair's outcome tests (and its
continuous columns) run over the episodes where neither agent errored, each agent's errored
episodes are a row of their own (outcome ``error``: how many and which, no test), and a note says
what the tests leave out.  An agent that errored in every episode of a pair gets that row and the
note only.  :func:`rmm_bench.compare.compare_runs` uses these.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ERROR", "PairErrors", "error_note", "error_row", "split_errors", "unpaired_errors"]

#: the outcome of an episode whose guardian raised, and the name of its row in a comparison
ERROR = "error"


@dataclass
class PairErrors:
    """A pair's common episodes split by errors."""

    n: int  # the episodes both agents have a row for
    tested: list[int]  # those where neither errored: the tests' episodes
    a: list[int]  # where A errored
    b: list[int]  # where B errored

    @property
    def any(self) -> bool:
        return bool(self.a or self.b)


def split_errors(common: list[int], ea: dict, eb: dict) -> PairErrors:
    """``common`` (episode numbers; ``ea``/``eb``: episode -> (row, run)) split by errors."""
    err_a = [e for e in common if ea[e][0]["outcome"] == ERROR]
    err_b = [e for e in common if eb[e][0]["outcome"] == ERROR]
    skip = set(err_a) | set(err_b)
    return PairErrors(len(common), [e for e in common if e not in skip], err_a, err_b)


def _which(eps: list[int], show: int) -> str:
    """'episode 3', 'episodes 3, 7', 'episodes 0, 1, 2, 3, 4 and 11 more' (none shown: '')."""
    shown = eps[:show]
    if not shown:
        return ""
    more = f" and {len(eps) - len(shown)} more" if len(eps) > len(shown) else ""
    return f"episode{'s' if len(eps) > 1 else ''} {', '.join(map(str, shown))}{more}"


def _errored(name: str, eps: list[int], n: int, show: int) -> str:
    which = _which(eps, show)
    return f"{name} errored in {f'all {n}' if len(eps) == n else len(eps)}" + (f" ({which})" if which else "")


def error_note(a: str, b: str, errs: PairErrors, show: int) -> str:
    """What a pair's tests leave out, e.g. ``lrmm vs cbf: outcome tests over the 14 episodes where
    neither errored; lrmm errored in 2 (episodes 3, 7)``."""
    said = ", ".join(_errored(name, eps, errs.n, show) for name, eps in ((a, errs.a), (b, errs.b)) if eps)
    if not errs.tested:
        return f"{a} vs {b}: no outcome test, as there is no episode where neither errored; {said}"
    return f"{a} vs {b}: outcome tests over the {len(errs.tested)} episodes where neither errored; {said}"


def error_row(a: str, b: str, label: str, errs: PairErrors, show: int, note: str) -> dict:
    """The pair's ``error`` row: each agent's errored share of the common episodes, the episodes
    only one of them errored in; no interval, no test (an error is no outcome to test)."""
    sa, sb = set(errs.a), set(errs.b)
    both = len(sa & sb)
    return {
        "group": label,
        "a": a,
        "b": b,
        "outcome": ERROR,
        "n": errs.n,
        "rate_a": len(sa) / errs.n if errs.n else math.nan,
        "rate_b": len(sb) / errs.n if errs.n else math.nan,
        "diff": math.nan,
        "lo": math.nan,
        "hi": math.nan,
        "a_only": len(sa) - both,
        "b_only": len(sb) - both,
        "both": both,
        "neither": errs.n - len(sa | sb),
        "p_value": math.nan,
        "a_only_episodes": [e for e in errs.a if e not in sb][:show],
        "b_only_episodes": [e for e in errs.b if e not in sa][:show],
        "note": note,
    }


def unpaired_errors(a: str, b: str, ra: list[dict], rb: list[dict]) -> tuple[list[dict], list[dict], dict | None, str]:
    """Unpaired: each agent's rows without its errored ones, its ``error`` row (None without
    errors) and the note (``""`` without errors)."""
    oa = [r for r in ra if r["outcome"] != ERROR]
    ob = [r for r in rb if r["outcome"] != ERROR]
    if len(oa) == len(ra) and len(ob) == len(rb):
        return oa, ob, None, ""
    parts = [
        f"{name} errored in {len(rows) - len(ok)} of {len(rows)}"
        for name, rows, ok in ((a, ra, oa), (b, rb, ob))
        if len(ok) < len(rows)
    ]
    if not oa or not ob:
        note = f"{a} vs {b}: no outcome test, as {a if not oa else b} errored in every episode; " + ", ".join(parts)
    else:
        note = f"{a} vs {b}: rates over each agent's episodes without an error; " + ", ".join(parts)
    row = {
        "group": "all episodes (unpaired)",
        "a": a,
        "b": b,
        "outcome": ERROR,
        "n_a": len(ra),
        "n_b": len(rb),
        "rate_a": (len(ra) - len(oa)) / len(ra) if ra else math.nan,
        "rate_b": (len(rb) - len(ob)) / len(rb) if rb else math.nan,
        "diff": math.nan,
        "lo": math.nan,
        "hi": math.nan,
        "note": note,
    }
    return oa, ob, row, note
