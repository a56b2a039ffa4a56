"""``rmm-bench compare``: agents compared on the episodes they all ran, pair by pair.

Offers :func:`compare_runs` (the Python entry: a :class:`Comparison` of pandas DataFrames);
the runs it reads come from :mod:`rmm_bench.compare_load`, the command line is
:mod:`rmm_bench.compare_command` and the statistics it rests on are in :mod:`rmm_bench.paired`.

Every agent of a run meets the same episodes, so two agents are compared episode by episode:
where one collides and the other does not (the discordant episodes) rather than by two rates
and their spreads.  Episodes pair when their world (env, start-shaping options, run seed), their
clock and their index agree and their stored start fingerprints are equal; results of several
directories pair under the same rule, so results of other code versions never pair silently
wrong.  ``docs/comparing.md`` explains the output.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rmm_bench.compare_errors import ERROR, error_note, error_row, split_errors, unpaired_errors
from rmm_bench.compare_load import (
    REFERENCE_PREFIX,
    Run,
    check_starts,
    episodes_by_group,
    read_runs,
    reference_runs,
    select,
)
from rmm_bench.compare_load import (
    left_out as runs_left_out,
)
from rmm_bench.compare_render import continuous_table, pairs_table
from rmm_bench.paired import concordance, mcnemar_exact, newcombe_paired, newcombe_unpaired, paired_bootstrap
from rmm_bench.store import results_database

#: ``read_runs`` under the name it had here (the collision taxonomy reads runs through it)
_read_runs = read_runs

__all__ = [
    "OUTCOMES",
    "Comparison",
    "compare_runs",
]

#: the outcome rows of a comparison, in order; ``avoidable collision`` is over the avoidable starts only
OUTCOMES = ("goal", "collision", "timeout", "avoidable collision")
#: the continuous columns: name -> (what it is, unit); decision time is measured, not reproduced
CONTINUOUS = {
    "time_to_goal": ("simulated time to the goal, episodes both agents finished", "s"),
    "intervention": ("share of the episode's simulated time the guardian was in control", "%"),
    "decision_ms": ("mean measured decision time (a timing value: differs between machines)", "ms"),
}
#: the prefix of the shipped reference results' agents (``rmm-bench compare --reference``)


# ---------------------------------------------------------------- the comparison


@dataclass
class Comparison:
    """What :func:`compare_runs` found.

    * ``pairs``: one row per (group, a, b, outcome); columns ``group`` (the world: env, seed,
      clock), ``a``, ``b``, ``outcome`` (:data:`OUTCOMES`), ``n`` (paired episodes; for
      ``avoidable collision`` the avoidable starts among them), ``rate_a``, ``rate_b``,
      ``diff`` (``rate_a - rate_b``), ``lo``, ``hi`` (its 95% interval), ``a_only``, ``b_only``,
      ``both``, ``neither``, ``p_value`` (exact McNemar), ``a_only_episodes``,
      ``b_only_episodes`` (the first discordant episode numbers), ``note``.  Rates are fractions.
      With ``paired`` False: ``n_a``, ``n_b`` instead of the counts, no p-value.  Where an agent
      of the pair errored (its guardian raised), the outcome rows count the episodes where
      neither errored, an ``error`` row counts the errored ones (no interval, no test; the only
      row of a pair where one agent errored in every episode), and ``note`` says so
      (:mod:`rmm_bench.compare_errors`).
    * ``continuous``: one row per (group, a, b, column): ``column`` (:data:`CONTINUOUS`),
      ``n``, ``mean_a``, ``mean_b``, ``diff``, ``lo``, ``hi`` (paired bootstrap), ``seed``,
      ``resamples``; over the episodes where neither errored.
    * ``floor``: one row per episode every compared agent failed (no goal) and none errored:
      ``group``, ``episode``, ``seed``, ``doomed``, and each agent's outcome.
    * ``notes``: what the reader must know (not assessed starts, errors, unpaired, ...).
    * ``left_out``: the runs compared with nothing, as no other agent ran their episodes (one
      string each: agent, world, database).
    """

    pairs: Any
    continuous: Any
    floor: Any
    notes: list[str]
    paired: bool
    agents: list[str]
    seed: int = 0
    resamples: int = 2000
    left_out: list[str] = field(default_factory=list)

    def to_markdown(self, show: int = 5) -> str:
        """The comparison as markdown tables (rates in %)."""
        out = []
        for group, pairs in self.pairs.groupby("group", sort=False):
            out.append(f"## {group}\n")
            out.append(pairs_table(pairs, self.paired, show))
            cont = self.continuous[self.continuous["group"] == group] if len(self.continuous) else self.continuous
            if len(cont):
                out.append(
                    f"\nContinuous columns: mean difference A - B with its paired bootstrap 95% interval "
                    f"(seed {self.seed}, {self.resamples} resamples)\n"
                )
                out.append(continuous_table(cont, {c: unit for c, (_, unit) in CONTINUOUS.items()}))
            floor = self.floor[self.floor["group"] == group] if len(self.floor) else self.floor
            if self.paired:
                out.append("\n" + _floor_line(floor, self.agents))
        out.extend(f"\nNote: {n}" for n in self.notes)
        return "\n".join(out).rstrip() + "\n"

    def to_csv(self) -> str:
        """The ``pairs`` table as CSV (rates as fractions; episode lists joined by spaces)."""
        df = self.pairs.copy()
        for col in ("a_only_episodes", "b_only_episodes"):
            if col in df:
                df[col] = [" ".join(map(str, v)) for v in df[col]]
        return str(df.to_csv(index=False))


def _floor_line(floor, agents: list[str]) -> str:
    n = len(floor)
    if not n:
        return f"Floor: no episode that every one of {', '.join(agents)} failed."
    cols = [c for c in floor.columns if c.startswith("outcome:")]
    collided = int((floor[cols] == "collision").all(axis=1).sum()) if cols else 0
    doomed = floor["doomed"]
    known = doomed.notna().all()
    d = f", {int((doomed == True).sum())} of them from doomed starts" if known else ""  # noqa: E712
    first = ",".join(map(str, floor["episode"].head(8)))
    return (
        f"Floor: {n} episodes that every one of {', '.join(agents)} failed (no goal), {collided} where "
        f"every one collided{d}; first: {first}"
    )


def _outcome_flags(row: dict, outcome: str) -> bool:
    return row["outcome"] == ("collision" if outcome == "avoidable collision" else outcome)


def _share(row: dict) -> float:
    st, act = row.get("sim_time"), row.get("active_sim_time")
    if row["outcome"] == "error" or not st or act is None:
        return math.nan
    return 100.0 * float(act) / float(st)


def _continuous_values(column: str, ra: dict, rb: dict) -> tuple[float, float]:
    if column == "time_to_goal":
        if ra["outcome"] == "goal" and rb["outcome"] == "goal":
            return float(ra["sim_time"]), float(rb["sim_time"])
        return math.nan, math.nan
    if column == "intervention":
        return _share(ra), _share(rb)
    a, b = ra.get("decision_mean"), rb.get("decision_mean")
    return (math.nan if a is None else 1e3 * float(a)), (math.nan if b is None else 1e3 * float(b))


def compare_runs(
    dirs: Sequence[str | Path],
    agents: Sequence[str] | None = None,
    *,
    unpaired: bool = False,
    reference: bool = False,
    seed: int = 0,
    resamples: int = 2000,
    show: int = 5,
    reference_dir: str | Path | None = None,
) -> Comparison:
    """Compare ``agents`` (names, or ``name@KEY``; default: every stored agent) of the results in
    ``dirs`` (results directories or ``results.db`` files, opened read-only) pair by pair, over
    the episodes both ran with the same world, clock, index and start; ``unpaired``: every
    episode of each, Newcombe's interval for independent rates; ``reference``: also the shipped
    reference results of the same worlds (agents ``ref:NAME``,
    :func:`rmm_bench.reference.reference_dbs`).  Raises ``ValueError`` naming what cannot be
    compared.  See :class:`Comparison` for what it returns."""
    import pandas as pd

    if resamples < 1:
        raise ValueError(f"--resamples must be >= 1, got {resamples}")
    if show < 0:
        raise ValueError(f"--show must be >= 0, got {show}")
    if not dirs:
        raise ValueError("compare: no results directory given (expected DIR [DIR2 ...])")
    runs: list[Run] = []
    for d in dirs:
        runs.extend(read_runs(results_database(d, "compare")))
    notes: list[str] = []
    if reference:
        ref_runs = reference_runs({r.group for r in runs}, reference_dir)
        runs.extend(ref_runs)
        if agents is not None and not any(a.startswith(REFERENCE_PREFIX) for a in agents):  # none named: all
            agents = list(agents) + sorted({r.label for r in ref_runs} - set(agents))
    selected = select(runs, agents)
    names = list(selected)
    if len(names) < 2:
        raise ValueError(
            f"--agent: compare needs at least two agents, got {', '.join(names) or 'none'} "
            f"(stored: {', '.join(sorted({r.label for r in runs}))})"
        )
    by_agent = {name: episodes_by_group(rs) for name, rs in selected.items()}
    if unpaired:
        pairs = _unpaired_pairs(names, by_agent, notes)
        notes.insert(
            0,
            "unpaired: every episode of each agent, Newcombe's hybrid score interval for independent rates; "
            "no McNemar test",
        )
        empty = pd.DataFrame()
        return Comparison(pairs, empty, empty, notes, False, names, seed, resamples)

    pair_rows: list[dict] = []
    cont_rows: list[dict] = []
    groups = [g for g in by_agent[names[0]] if all(g in by_agent[n] for n in names)]
    left_out = runs_left_out(selected, by_agent)
    for a_i, a in enumerate(names):
        for b in names[a_i + 1 :]:
            common_groups = set(by_agent[a]) & set(by_agent[b])
            if not common_groups:
                ga = "; ".join(sorted({r.describe() for r in selected[a]}))
                gb = "; ".join(sorted({r.describe() for r in selected[b]}))
                raise ValueError(
                    f"{a} and {b} ran no episode alike ({a}: {ga}; {b}: {gb}): env, options, seed and clock must "
                    f"match; compare them with --unpaired"
                )
            for group in sorted(common_groups):
                ea, eb = by_agent[a][group], by_agent[b][group]
                common = sorted(set(ea) & set(eb))
                label = next(iter(ea.values()))[1].describe()
                if not common:
                    continue
                check_starts(a, b, label, common, ea, eb)
                errs = split_errors(common, ea, eb)  # the tests run where neither errored
                note = error_note(a, b, errs, show) if errs.any else ""
                doomed = _doomed_of(ea, eb, errs.tested)
                if errs.tested:
                    pair_rows.extend(_pair_rows(a, b, label, errs.tested, ea, eb, doomed, show, note))
                    cont_rows.extend(_continuous_rows(a, b, label, errs.tested, ea, eb, seed, resamples))
                if errs.any:
                    pair_rows.append(error_row(a, b, label, errs, show, note))
                    notes.append(f"{label}: {note}")
                    notes.append(f"{label}: the floor leaves out the episodes where an agent errored")
                if errs.tested and any(doomed.get(e) is None for e in errs.tested):
                    notes.append(
                        f"{label}: starts not assessed for doomed (the env has no doomed test, or the run "
                        f"predates it): no 'avoidable collision' row"
                    )
    if not pair_rows:
        raise ValueError(f"{', '.join(names)}: no episode with a result that the agents ran alike")
    floor = _floor(names, by_agent, groups)
    notes = list(dict.fromkeys(notes))
    pairs = pd.DataFrame(pair_rows)
    return Comparison(pairs, pd.DataFrame(cont_rows), floor, notes, True, names, seed, resamples, left_out)


def _doomed_of(ea: dict, eb: dict, common: list[int]) -> dict[int, bool | None]:
    out = {}
    for e in common:
        da = ea[e][1].doomed.get(e)
        db = eb[e][1].doomed.get(e)
        out[e] = da if da is not None else db
    return out


def _pair_rows(a, b, label, common, ea, eb, doomed, show, note) -> list[dict]:
    rows = []
    assessed = all(doomed.get(e) is not None for e in common)
    for outcome in OUTCOMES:
        eps = common
        if outcome == "avoidable collision":
            if not assessed:
                continue
            eps = [e for e in common if doomed[e] is False]
        fa = np.array([_outcome_flags(ea[e][0], outcome) for e in eps], bool)
        fb = np.array([_outcome_flags(eb[e][0], outcome) for e in eps], bool)
        both, a_only, b_only, neither = concordance(fa, fb)
        d, lo, hi = newcombe_paired(both, a_only, b_only, neither)
        n = len(eps)
        rows.append(
            {
                "group": label,
                "a": a,
                "b": b,
                "outcome": outcome,
                "n": n,
                "rate_a": (both + a_only) / n if n else math.nan,
                "rate_b": (both + b_only) / n if n else math.nan,
                "diff": d,
                "lo": lo,
                "hi": hi,
                "a_only": a_only,
                "b_only": b_only,
                "both": both,
                "neither": neither,
                "p_value": mcnemar_exact(a_only, b_only),
                "a_only_episodes": [e for e, x, y in zip(eps, fa, fb, strict=True) if x and not y][:show],
                "b_only_episodes": [e for e, x, y in zip(eps, fa, fb, strict=True) if y and not x][:show],
                "note": note,
            }
        )
    return rows


def _continuous_rows(a, b, label, common, ea, eb, seed, resamples) -> list[dict]:
    rows = []
    for column in CONTINUOUS:
        values = np.array([_continuous_values(column, ea[e][0], eb[e][0]) for e in common], float).reshape(-1, 2)
        keep = ~np.isnan(values).any(axis=1)
        x, y = values[keep, 0], values[keep, 1]
        d, lo, hi = paired_bootstrap(x, y, seed, resamples)
        rows.append(
            {
                "group": label,
                "a": a,
                "b": b,
                "column": column,
                "n": int(keep.sum()),
                "mean_a": float(x.mean()) if x.size else math.nan,
                "mean_b": float(y.mean()) if y.size else math.nan,
                "diff": d,
                "lo": lo,
                "hi": hi,
                "seed": seed,
                "resamples": resamples,
            }
        )
    return rows


def _floor(names: list[str], by_agent: dict, groups: list) -> Any:
    import pandas as pd

    rows = []
    for group in groups:
        per = [by_agent[n][group] for n in names]
        common = sorted(set.intersection(*(set(p) for p in per)))
        for e in common:
            outcomes = [p[e][0]["outcome"] for p in per]
            if "goal" in outcomes or ERROR in outcomes:  # an agent that raised did not fail there
                continue
            flags = [p[e][1].doomed.get(e) for p in per]
            known = [f for f in flags if f is not None]
            rows.append(
                {
                    "group": per[0][e][1].describe(),
                    "episode": e,
                    "seed": per[0][e][0]["seed"],
                    "doomed": known[0] if known else None,
                    **{f"outcome:{n}": o for n, o in zip(names, outcomes, strict=True)},
                }
            )
    cols = ["group", "episode", "seed", "doomed"] + [f"outcome:{n}" for n in names]
    return pd.DataFrame(rows, columns=cols)


def _unpaired_pairs(names: list[str], by_agent: dict, notes: list[str]) -> Any:
    """Every pair's rates over all of each agent's episodes without an error (``notes``: what
    the errors left out)."""
    import pandas as pd

    rows = []
    for a_i, a in enumerate(names):
        for b in names[a_i + 1 :]:
            ra = [row for eps in by_agent[a].values() for row, _ in eps.values()]
            rb = [row for eps in by_agent[b].values() for row, _ in eps.values()]
            ra, rb, error, note = unpaired_errors(a, b, ra, rb)
            for outcome in OUTCOMES[:3] if ra and rb else ():
                xa = sum(_outcome_flags(r, outcome) for r in ra)
                xb = sum(_outcome_flags(r, outcome) for r in rb)
                d, lo, hi = newcombe_unpaired(xa, len(ra), xb, len(rb))
                rows.append(
                    {
                        "group": "all episodes (unpaired)",
                        "a": a,
                        "b": b,
                        "outcome": outcome,
                        "n_a": len(ra),
                        "n_b": len(rb),
                        "rate_a": xa / len(ra) if ra else math.nan,
                        "rate_b": xb / len(rb) if rb else math.nan,
                        "diff": d,
                        "lo": lo,
                        "hi": hi,
                        "note": note,
                    }
                )
            if error is not None:
                rows.append(error)
                notes.append(note)
    return pd.DataFrame(rows)
