"""``rmm-bench compare``'s input: the stored runs of results databases, grouped into what pairs.

Offers :func:`read_runs` (one database's runs, the rows a comparison reads), :func:`select`
(the runs ``--agent`` names), :func:`episodes_by_group` and :func:`reference_runs` (the shipped
reference results of the same episodes); :mod:`rmm_bench.compare` compares them.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rmm_bench.names import did_you_mean
from rmm_bench.reference import reference_dbs
from rmm_bench.store import RETRIED_ERRORS, ResultsStore
from rmm_envs.starts import world_key

__all__ = [
    "REFERENCE_PREFIX",
    "Run",
    "check_starts",
    "episodes_by_group",
    "left_out",
    "read_runs",
    "reference_runs",
    "select",
]

#: the prefix of the shipped reference results' agents (``--reference``)
REFERENCE_PREFIX = "ref:"


@dataclass
class Run:
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
    def disturbances(self) -> str:
        """The run's disturbances (``; `` between them), ``""`` when undisturbed: runs pair only
        under the same ones (their starts are the same; what happens after is not)."""
        return "; ".join(self.config.get("env_kwargs", {}).get("disturbances", []) or [])

    @property
    def group(self) -> tuple[str, ...]:
        return self.world, self.clock, self.disturbances

    def describe(self) -> str:
        c = self.config
        dist = f" disturbances {self.disturbances}" if self.disturbances else ""
        return f"{c.get('env_id')} seed {c.get('seed')} clock {self.clock}{dist}"


_COLUMNS = "episode, seed, outcome, error_kind, steps, sim_time, active_sim_time, decision_mean, start"


def _clock(config: dict) -> str:
    return str(config.get("env_kwargs", {}).get("clock", "wall"))


def read_runs(db: Path, prefix: str = "") -> list[Run]:
    """Every run stored in ``db`` with its rows (episodes without a result left out) and doomed flags."""

    store = ResultsStore(db, read_only=True)
    try:
        runs = []
        for key, agent, config in store.db.execute("SELECT run_key, agent, config FROM runs ORDER BY created, rowid"):
            config = json.loads(config)
            run = Run(
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


def select(runs: list[Run], names: Sequence[str] | None) -> dict[str, list[Run]]:
    """The runs of each named agent (``name`` or ``name@KEY``, KEY a prefix of a run key); with no
    names, every stored agent.  One agent's runs must not share a world and clock (say which)."""
    stored = sorted({r.label for r in runs})
    if names is None:
        names = stored
    out: dict[str, list[Run]] = {}
    for name in names:
        agent, _, key = name.partition("@")
        chosen = [r for r in runs if r.label == agent and r.run_key.startswith(key)]
        if not chosen:
            what = f"no run of {agent!r}" if not key else f"no run of {agent!r} whose key starts with {key!r}"
            ref = agent.startswith(REFERENCE_PREFIX) and not any(s.startswith(REFERENCE_PREFIX) for s in stored)
            near = did_you_mean(agent, stored) if agent not in stored and not ref else ""
            raise ValueError(
                f"--agent {name}: {what} is stored{near} (expected one of: {', '.join(stored) or 'none'})"
                + ("; the shipped reference results (ref:NAME) are compared with --reference" if ref else "")
            )
        by_group: dict[tuple[str, ...], list[Run]] = {}
        for r in chosen:
            by_group.setdefault(r.group, []).append(r)
        for group_runs in by_group.values():
            keys = sorted({r.run_key for r in group_runs})
            if len(keys) > 1:
                raise ValueError(
                    f"--agent {name}: {len(keys)} runs of {agent!r} ran the same episodes "
                    f"({group_runs[0].describe()}: runs {', '.join(keys)}, other options or files); "
                    f"name one as {agent}@KEY"
                )
        out[name] = chosen
    return out


def episodes_by_group(runs: list[Run]) -> dict[tuple[str, ...], dict[int, tuple[dict, Run]]]:
    """One agent's rows by group and episode; the same run in several databases (shards of one
    run) is joined, and an episode stored differently in two of them is refused."""
    out: dict[tuple[str, ...], dict[int, tuple[dict, Run]]] = {}
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


def reference_runs(groups: set[tuple[str, ...]], folder: str | Path | None) -> list[Run]:

    dbs = reference_dbs(folder)
    shipped: list[Run] = []
    for db in dbs:
        shipped.extend(read_runs(db, prefix=REFERENCE_PREFIX))
    matching = [r for r in shipped if r.group in groups]
    if not matching:
        worlds = "; ".join(sorted({r.describe() for r in shipped})) or "none"
        raise ValueError(
            f"--reference: no shipped reference result ran the same episodes as the given runs (same env, "
            f"options, seed and clock); shipped: {worlds}"
        )
    return matching


def check_starts(a: str, b: str, group_label: str, common: list[int], ea: dict, eb: dict) -> None:
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


def left_out(selected: dict[str, list[Run]], by_agent: dict) -> list[str]:
    """The runs whose episodes no other agent ran (``cbf`` of seed 1 beside ``lrmm`` of seed 0 alone)."""
    out = []
    for name, runs in selected.items():
        others = {g for n in selected if n != name for g in by_agent[n]}
        out += [f"{name} ({r.describe()}, in {r.source})" for r in runs if r.group not in others]
    return list(dict.fromkeys(out))
