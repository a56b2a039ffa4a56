"""``rmm-bench compare``: agents compared on the episodes they all ran, pair by pair.

Offers :func:`compare_runs` (the Python entry: a :class:`Comparison` of pandas DataFrames)
and the command (:func:`build_parser`, :func:`cmd`); the statistics it rests on are in
:mod:`rmm_bench.paired`.

Every agent of a run meets the same episodes, so two agents are compared episode by episode:
where one collides and the other does not (the discordant episodes) rather than by two rates
and their spreads.  Episodes pair when their world (env, start-shaping options, run seed), their
clock and their index agree and their stored start fingerprints are equal; results of several
directories pair under the same rule, so results of other code versions never pair silently
wrong.  ``docs/comparing.md`` explains the output.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rmm_bench.compare_errors import ERROR, error_note, error_row, split_errors, unpaired_errors
from rmm_bench.compare_render import continuous_table, pairs_table
from rmm_bench.names import did_you_mean
from rmm_bench.outputs import check_output, write_output
from rmm_bench.paired import concordance, mcnemar_exact, newcombe_paired, newcombe_unpaired, paired_bootstrap
from rmm_bench.store import RETRIED_ERRORS, ResultsStore, results_database

__all__ = [
    "OUTCOMES",
    "Comparison",
    "build_parser",
    "cmd",
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
REFERENCE_PREFIX = "ref:"


# ---------------------------------------------------------------- loading


@dataclass
class _Run:
    """One stored run of one agent: the rows this comparison reads."""

    label: str  # the agent's name in the comparison
    source: Path  # the database
    run_key: str
    config: dict
    world: str  # rmm_envs.starts.world_key
    clock: str
    rows: dict[int, dict] = field(default_factory=dict)  # episode -> row
    doomed: dict[int, bool | None] = field(default_factory=dict)  # episode -> flag

    @property
    def group(self) -> tuple[str, str]:
        return self.world, self.clock

    def describe(self) -> str:
        c = self.config
        return f"{c.get('env_id')} seed {c.get('seed')} clock {self.clock}"


_COLUMNS = "episode, seed, outcome, error_kind, steps, sim_time, active_sim_time, decision_mean, start"


def _clock(config: dict) -> str:
    return str(config.get("env_kwargs", {}).get("clock", "wall"))


def _read_runs(db: Path, prefix: str = "") -> list[_Run]:
    """Every run stored in ``db`` with its rows (episodes without a result left out) and doomed flags."""
    from rmm_envs.starts import world_key

    store = ResultsStore(db, read_only=True)
    try:
        runs = []
        for key, agent, config in store.db.execute("SELECT run_key, agent, config FROM runs ORDER BY created, rowid"):
            config = json.loads(config)
            run = _Run(
                label=prefix + agent,
                source=db,
                run_key=key,
                config=config,
                world=world_key(config["env_id"], config.get("env_kwargs", {}), int(config.get("seed", 0))),
                clock=_clock(config),
            )
            names = [r[1] for r in store.db.execute("PRAGMA table_info(episodes)")]
            cols = ", ".join(c.strip() if c.strip() in names else f"NULL AS {c.strip()}" for c in _COLUMNS.split(","))
            cur = store.db.execute(f"SELECT {cols} FROM episodes WHERE run_key = ? ORDER BY episode", (key,))
            fields = [d[0] for d in cur.description]
            for values in cur.fetchall():
                row = dict(zip(fields, values, strict=True))
                if row["outcome"] == "error" and (row["error_kind"] or "guardian") in RETRIED_ERRORS:
                    continue  # no result: lost, over time, or a failure of the run
                run.rows[int(row["episode"])] = row
            run.doomed = {e: s["doomed"] for e, s in store.starts(run.world).items()}
            runs.append(run)
        return runs
    finally:
        store.close()


def _select(runs: list[_Run], names: Sequence[str] | None) -> dict[str, list[_Run]]:
    """The runs of each named agent (``name`` or ``name@KEY``, KEY a prefix of a run key); with no
    names, every stored agent.  One agent's runs must not share a world and clock (say which)."""
    stored = sorted({r.label for r in runs})
    if names is None:
        names = stored
    out: dict[str, list[_Run]] = {}
    for name in names:
        agent, _, key = name.partition("@")
        chosen = [r for r in runs if r.label == agent and r.run_key.startswith(key)]
        if not chosen:
            what = f"no run of {agent!r}" if not key else f"no run of {agent!r} whose key starts with {key!r}"
            ref = agent.startswith(REFERENCE_PREFIX) and not any(s.startswith(REFERENCE_PREFIX) for s in stored)
            near = did_you_mean(agent, stored) if agent not in stored and not ref else ""
            raise ValueError(
                f"--agents {name}: {what} is stored{near} (expected one of: {', '.join(stored) or 'none'})"
                + ("; the shipped reference results (ref:NAME) are compared with --reference" if ref else "")
            )
        by_group: dict[tuple[str, str], list[_Run]] = {}
        for r in chosen:
            by_group.setdefault(r.group, []).append(r)
        for group_runs in by_group.values():
            keys = sorted({r.run_key for r in group_runs})
            if len(keys) > 1:
                raise ValueError(
                    f"--agents {name}: {len(keys)} runs of {agent!r} ran the same episodes "
                    f"({group_runs[0].describe()}: runs {', '.join(keys)}, other options or files); "
                    f"name one as {agent}@KEY"
                )
        out[name] = chosen
    return out


def _episodes(runs: list[_Run]) -> dict[tuple[str, str], dict[int, tuple[dict, _Run]]]:
    """One agent's rows by group and episode; the same run in several databases (shards of one
    run) is joined, and an episode stored differently in two of them is refused."""
    out: dict[tuple[str, str], dict[int, tuple[dict, _Run]]] = {}
    for run in runs:
        rows = out.setdefault(run.group, {})
        for e, row in run.rows.items():
            if e in rows and rows[e][0]["outcome"] != row["outcome"]:
                raise ValueError(
                    f"{run.label} episode {e} is stored with outcome {rows[e][0]['outcome']} in "
                    f"{rows[e][1].source} and {row['outcome']} in {run.source}: merge them first "
                    f"(rmm-bench merge) or compare one of them"
                )
            rows.setdefault(e, (row, run))
    return out


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


def _check_starts(a: str, b: str, group_label: str, common: list[int], ea: dict, eb: dict) -> None:
    """Paired episodes must have started alike: equal fingerprints, or (before fingerprints were
    stored) the same database."""
    for e in common:
        (ra, run_a), (rb, run_b) = ea[e], eb[e]
        fa, fb = ra.get("start"), rb.get("start")
        if fa is not None and fb is not None:
            if fa != fb:
                raise ValueError(
                    f"{a} and {b} ({group_label}): episode {e} started differently (start fingerprint {fa} in "
                    f"{run_a.source}, {fb} in {run_b.source}): the runs come from code that shapes starts "
                    f"differently; compare them with --unpaired"
                )
        elif run_a.source != run_b.source:
            raise ValueError(
                f"{a} and {b} ({group_label}): episode {e} has no start fingerprint in "
                f"{run_a.source if fa is None else run_b.source} (stored before results-store schema 3), so its "
                f"start cannot be checked against the other database's; compare them with --unpaired"
            )


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
    runs: list[_Run] = []
    for d in dirs:
        runs.extend(_read_runs(results_database(d, "compare")))
    notes: list[str] = []
    if reference:
        ref_runs = _reference_runs({r.group for r in runs}, reference_dir)
        runs.extend(ref_runs)
        if agents is not None and not any(a.startswith(REFERENCE_PREFIX) for a in agents):  # none named: all
            agents = list(agents) + sorted({r.label for r in ref_runs} - set(agents))
    selected = _select(runs, agents)
    names = list(selected)
    if len(names) < 2:
        raise ValueError(
            f"--agents: compare needs at least two agents, got {', '.join(names) or 'none'} "
            f"(stored: {', '.join(sorted({r.label for r in runs}))})"
        )
    by_agent = {name: _episodes(rs) for name, rs in selected.items()}
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
    left_out = _left_out(selected, by_agent)
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
                _check_starts(a, b, label, common, ea, eb)
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


def _left_out(selected: dict[str, list[_Run]], by_agent: dict) -> list[str]:
    """The runs whose episodes no other agent ran (``cbf`` of seed 1 beside ``lrmm`` of seed 0 alone)."""
    out = []
    for name, runs in selected.items():
        others = {g for n in selected if n != name for g in by_agent[n]}
        out += [f"{name} ({r.describe()}, in {r.source})" for r in runs if r.group not in others]
    return list(dict.fromkeys(out))


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


def _reference_runs(groups: set[tuple[str, str]], folder: str | Path | None) -> list[_Run]:
    from rmm_bench.reference import reference_dbs

    dbs = reference_dbs(folder)
    shipped: list[_Run] = []
    for db in dbs:
        shipped.extend(_read_runs(db, prefix=REFERENCE_PREFIX))
    matching = [r for r in shipped if r.group in groups]
    if not matching:
        worlds = "; ".join(sorted({r.describe() for r in shipped})) or "none"
        raise ValueError(
            f"--reference: no shipped reference result ran the same episodes as the given runs (same env, "
            f"options, seed and clock); shipped: {worlds}"
        )
    return matching


# ---------------------------------------------------------------- the command


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench compare`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench compare",
        description="Compare agents pair by pair on the episodes they all ran (same world, seed, clock and "
        "start): rate differences with paired 95%% intervals, the exact McNemar test on the discordant "
        "episodes and their numbers (for rmm-bench replay), the floor no agent lifts, and paired bootstrap "
        "intervals of the continuous columns.  Opens the databases read-only.",
    )
    p.add_argument("dirs", nargs="+", metavar="DIR", help="results directories (or results.db files)")
    p.add_argument(
        "--agents",
        default=None,
        help="comma-separated agents, NAME or NAME@KEY (KEY: a prefix of the run key); default: every stored one",
    )
    p.add_argument("--unpaired", action="store_true", help="compare every episode of each agent as independent samples")
    p.add_argument(
        "--reference",
        action="store_true",
        help="also compare with the shipped reference results of the same episodes (agents ref:NAME)",
    )
    p.add_argument("--format", default="md", help="md (default) or csv")
    p.add_argument("--out", type=Path, default=None, metavar="FILE", help="write the table there (default: stdout)")
    p.add_argument("--seed", type=int, default=0, help="seed of the paired bootstrap (default 0)")
    p.add_argument("--resamples", type=int, default=2000, help="bootstrap resamples (default 2000)")
    p.add_argument("--show", type=int, default=5, help="discordant episode numbers shown per side (default 5)")
    return p


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench compare``; bad input raises ``ValueError`` (exit 2 through the CLI)."""
    args = build_parser().parse_args(argv)
    if args.format not in ("md", "csv"):
        raise ValueError(f"--format {args.format!r}: expected md or csv")
    agents = None
    if args.agents is not None:
        agents = [a.strip() for a in args.agents.split(",") if a.strip()]
        if not agents:
            raise ValueError(f"--agents {args.agents!r}: expected comma-separated agent names")
    existed = args.out is not None and args.out.exists()
    if args.out is not None:  # before anything is read: never over a database it reads (or any other)
        check_output(args.out, "--out", reads=[results_database(d, "compare") for d in args.dirs])
    comparison = compare_runs(
        args.dirs,
        agents,
        unpaired=args.unpaired,
        reference=args.reference,
        seed=args.seed,
        resamples=args.resamples,
        show=args.show,
    )
    if comparison.left_out:  # said in one line, never dropped silently
        left = "; ".join(comparison.left_out)
        print(f"rmm-bench compare: note: left out, as no other agent ran their episodes: {left}", file=sys.stderr)
    text = comparison.to_markdown(args.show) if args.format == "md" else comparison.to_csv()
    if args.out is None:
        sys.stdout.write(text)
    else:
        write_output(args.out, lambda tmp: tmp.write_text(text), existed=existed)
        print(f"wrote {args.out}", file=sys.stderr)
    return 0
