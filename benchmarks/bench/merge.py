"""``rmm-bench merge DIR1 DIR2 ... --out OUT``: results of several machines joined into one database.

Offers :func:`merge` (the Python entry, returning a :class:`MergeSummary`), :class:`MergeConflict`
and the command (:func:`build_parser`, :func:`cmd`).

Episodes are bit-identical on every machine for a seed (fixed clock), so a run split with
``--shard K/N`` over machines, or simply run twice, can be joined: every episode stored in
more than one input is compared column by column (timing columns aside), and a difference
is refused, naming the episode, the agent, the column and both values.  The inputs are opened
read-only and never changed; the output is built in a temporary file beside it and renamed
into place only when complete, so a crash or Ctrl-C leaves no half-merged database.
``docs/machines.md`` explains the workflow.
"""

from __future__ import annotations

import argparse
import json
import os
import sqlite3
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from rmm_bench.outputs import OutputExists, publish
from rmm_bench.replay import compare_rows
from rmm_bench.report import CONFIGURATION, write_report
from rmm_bench.runner import REPRODUCIBLE_CLOCKS
from rmm_bench.store import EPISODE_FIELDS, RETRIED_ERRORS, ResultsStore, pid_alive, results_database
from rmm_envs.starts import world_key

__all__ = ["MergeConflict", "MergeSummary", "build_parser", "cmd", "merge"]


class MergeConflict(ValueError):
    """Two inputs disagree: the same episode stored with different results, or runs of different
    configurations under one agent name.  Nothing is written."""


@dataclass
class MergeSummary:
    """What :func:`merge` did: the output database, the parts joined, the episodes written, the
    overlapping episodes checked (equal in every compared column) and the agents."""

    out: Path
    parts: int = 0
    episodes: int = 0
    overlaps: int = 0
    agents: list[str] = field(default_factory=list)


def _reproducible(config: dict) -> bool:
    """Whether a run's episodes are the same on every machine: a blocking env (no clock) or a
    fixed (or manual) clock."""
    clock = config.get("env_kwargs", {}).get("clock")
    return clock is None or str(clock).split(":")[0].strip().lower() in REPRODUCIBLE_CLOCKS


def _difference(kept: dict, new: dict, reproducible: bool) -> tuple[str, object, object] | None:
    """The first column where two stored rows of one episode differ: timing columns aside for a
    reproducible run (:func:`rmm_bench.replay.compare_rows`), every column for a wall-clock one."""
    if reproducible:
        return compare_rows(kept, new, clock_reproduced=True)
    for col in kept:
        if col in ("run_key", "episode"):
            continue
        if kept[col] != new.get(col) and not (kept[col] != kept[col] and new.get(col) != new.get(col)):  # NaN == NaN
            return col, kept[col], new.get(col)
    return None


def _no_result(row: dict) -> bool:
    return row["outcome"] == "error" and (row.get("error_kind") or "guardian") in RETRIED_ERRORS


def _last_run_invocation(store: ResultsStore) -> dict | None:
    try:
        return store.invocation(None, command="run")
    except LookupError:
        return None


def _configuration(args: dict) -> tuple:
    return tuple(args.get(k) for k in CONFIGURATION)


def merge(out: str | Path, inputs: list[str | Path], write_tables: bool = True) -> MergeSummary:
    """Join the results databases of ``inputs`` (results directories or ``results.db`` files)
    into ``out``/results.db, which must not exist yet.  Raises :class:`MergeConflict` (nothing
    written) when two inputs disagree, ``ValueError`` on bad input.  ``write_tables``: also write
    the merged run's tables and figure into ``out``, as ``rmm-bench report out`` would."""
    out = Path(out)
    if len(inputs) < 1:
        raise ValueError("merge: no input given (expected DIR1 DIR2 ... --out OUT)")
    dbs = [results_database(p, "merge") for p in inputs]
    target = out / "results.db"
    for given, db in zip(inputs, dbs, strict=True):
        if db.resolve() == target.resolve():
            raise ValueError(f"merge: --out {out} is also an input ({given}); merge into a new directory")
    if len({db.resolve() for db in dbs}) < len(dbs):
        raise ValueError("merge: an input is named twice")
    if target.exists():
        raise ValueError(f"merge: {target} exists already; merge into a new directory (the inputs stay as they are)")
    if out.exists() and not out.is_dir():
        raise ValueError(f"merge: --out {out} is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    _remove_abandoned(out)
    tmp = out / f"{_MERGING}{os.getpid()}"
    _remove(tmp)
    try:
        summary = _merge_into(tmp, dbs, inputs)
        con = sqlite3.connect(tmp)  # one self-contained file before it is moved into place
        con.execute("PRAGMA journal_mode=DELETE")
        con.close()
        try:
            publish(tmp, target, existed=False)  # never over a results.db another merge put there meanwhile
        except OutputExists:
            raise MergeConflict(
                f"merge: {target} appeared while this merge ran (another merge into {out}?); it is left as it is "
                "and this merge wrote nothing: merge into a new directory"
            ) from None
    finally:
        _remove(tmp)
    summary.out = target
    if write_tables:
        store = ResultsStore(target, read_only=True)
        try:
            write_report(store, out, store.invocation(None, command="run"), quiet=True)
        finally:
            store.close()
    return summary


#: The name of a merge's database while it is built, followed by the merging process's id.
_MERGING = ".results.db.merging-"


def _remove(db: Path) -> None:
    for suffix in ("", "-wal", "-shm", "-journal"):
        Path(f"{db}{suffix}").unlink(missing_ok=True)


def _remove_abandoned(out: Path) -> None:
    """Remove what a merge into ``out`` killed before it could clean up (``kill -9``, a power
    cut) left: its half-built database and SQLite's files beside it, when its process is gone."""
    for leftover in out.glob(f"{_MERGING}*"):
        pid = leftover.name[len(_MERGING) :].split("-")[0]
        if pid.isdigit() and int(pid) != os.getpid() and not pid_alive(int(pid)):
            leftover.unlink(missing_ok=True)


def _merge_into(tmp: Path, dbs: list[Path], names: list) -> MergeSummary:
    summary = MergeSummary(out=tmp)
    merged = ResultsStore(tmp)
    w = merged.db
    try:
        runs: dict[str, dict] = {}  # run_key -> {agent, config, source}
        rows: dict[tuple[str, int], tuple[dict, str]] = {}  # (run_key, episode) -> (row, source)
        traces: dict[tuple[str, int], tuple] = {}
        starts: dict[tuple[str, int], tuple] = {}
        invocations = []
        parts = []
        columns = list(EPISODE_FIELDS)
        for db, name in zip(dbs, names, strict=True):
            src = ResultsStore(db, read_only=True)
            try:
                _read_part(src, str(name), runs, rows, traces, starts, summary)
                inv = _last_run_invocation(src)
                if inv is not None:
                    invocations.append((inv, str(name)))
                parts.append(_part(src, str(name), inv))
            finally:
                src.close()
        _check_agents(runs)
        with w:
            for key, run in runs.items():
                w.execute(
                    "INSERT INTO runs (run_key, agent, created, config, provenance) VALUES (?, ?, ?, ?, ?)",
                    (key, run["agent"], run["created"], json.dumps(run["config"], sort_keys=True), run["provenance"]),
                )
            w.executemany(
                f"INSERT INTO episodes ({', '.join(columns)}) VALUES ({', '.join('?' * len(columns))})",
                [[row.get(c) for c in columns] for (row, _) in rows.values()],
            )
            w.executemany(
                "INSERT INTO clock_traces (run_key, episode, codec, n, laps) VALUES (?, ?, ?, ?, ?)",
                [(k, e, *v) for (k, e), v in traces.items() if (k, e) in rows],
            )
            w.executemany(
                "INSERT INTO starts (world_key, episode, seed, fingerprint, doomed, method, seconds) "
                "VALUES (?, ?, ?, ?, ?, ?, ?)",
                [(wk, e, *v) for (wk, e), v in starts.items()],
            )
            now = time.time()
            w.executemany(
                "INSERT INTO parts (source, host, package_version, git_revision, argv, shard, started, finished, "
                "episodes, run_keys, merged) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                [(*p, now) for p in parts],
            )
            if invocations:
                _merged_invocation(w, invocations, runs)
        summary.parts = len(parts)
        summary.episodes = len(rows)
        summary.agents = sorted({r["agent"] for r in runs.values()})
        return summary
    finally:
        merged.close()


def _read_part(src: ResultsStore, name: str, runs, rows, traces, starts, summary: MergeSummary) -> None:
    for key, agent, created, config, provenance in src.db.execute(
        "SELECT run_key, agent, created, config, provenance FROM runs"
    ):
        config = json.loads(config)
        if key in runs and runs[key]["config"] != config:  # the key hashes the config: a damaged file
            raise MergeConflict(f"run {key} has another configuration in {name} than in {runs[key]['source']}")
        runs.setdefault(
            key, {"agent": agent, "created": created, "config": config, "provenance": provenance, "source": name}
        )
    cur = src.db.execute("SELECT * FROM episodes ORDER BY run_key, episode")
    fields = [d[0] for d in cur.description]
    for values in cur:
        row = dict(zip(fields, values, strict=True))
        k = (row["run_key"], int(row["episode"]))
        if k not in rows:
            rows[k] = (row, name)
            continue
        kept, where = rows[k]
        if _no_result(kept) and not _no_result(row):  # a rerun elsewhere gave the result this part lacked
            rows[k] = (row, name)
            continue
        if _no_result(row):
            continue
        summary.overlaps += 1
        reproducible = _reproducible(runs[row["run_key"]]["config"])
        diff = _difference(kept, row, reproducible)
        if diff is not None:
            col, a, b = diff
            why = (
                ""
                if reproducible
                else " (a wall-clock run: its episodes depend on the machine, overlaps must be identical)"
            )
            raise MergeConflict(
                f"episode {k[1]} of {row['agent']} (run {k[0]}) differs in {col}: {a!r} in {where}, {b!r} in {name}{why}; "
                f"nothing was written"
            )
    if src._table_exists("clock_traces"):
        for key, e, codec, n, laps in src.db.execute("SELECT run_key, episode, codec, n, laps FROM clock_traces"):
            if rows.get((key, int(e)), (None, None))[1] == name:
                traces[(key, int(e))] = (codec, n, laps)
    if src._table_exists("starts"):
        for wk, e, seed, fp, doomed, method, seconds in src.db.execute(
            "SELECT world_key, episode, seed, fingerprint, doomed, method, seconds FROM starts"
        ):
            k2 = (wk, int(e))
            if k2 in starts and (starts[k2][1], starts[k2][2]) != (fp, doomed):
                raise MergeConflict(
                    f"the start of episode {e} (world {wk}) differs: fingerprint {starts[k2][1]} doomed "
                    f"{starts[k2][2]} in one input, {fp} doomed {doomed} in {name}; nothing was written"
                )
            starts.setdefault(k2, (seed, fp, doomed, method, seconds))


def _part(src: ResultsStore, name: str, inv: dict | None) -> tuple:
    """The ``parts`` row of one input: the provenance of its last run (or of its newest run record)."""
    prov = {}
    row = src.db.execute("SELECT provenance FROM runs ORDER BY created DESC, rowid DESC LIMIT 1").fetchone()
    if row is not None:
        prov = json.loads(row[0])
    n = src.db.execute("SELECT COUNT(*) FROM episodes").fetchone()[0]
    keys = [r[0] for r in src.db.execute("SELECT run_key FROM runs ORDER BY run_key")]
    args = (inv or {}).get("args", {})
    return (
        name,
        (inv or {}).get("host"),
        prov.get("package_version"),
        prov.get("git_revision"),
        json.dumps(prov.get("argv")),
        args.get("shard"),
        (inv or {}).get("created"),
        (inv or {}).get("updated"),
        int(n),
        json.dumps(keys),
    )


def _check_agents(runs: dict[str, dict]) -> None:
    """One agent name, one configuration per world: two runs of an agent on the same episodes
    (env, options, seed, clock) with other guardian options or files are refused."""

    seen: dict[tuple, tuple[str, dict]] = {}
    for key, run in runs.items():
        c = run["config"]
        world = (
            run["agent"],
            world_key(c["env_id"], c.get("env_kwargs", {}), int(c.get("seed", 0))),
            str(c.get("env_kwargs", {}).get("clock")),
        )
        if world in seen and seen[world][0] != key:
            other_key, other = seen[world]
            differ = sorted(k for k in set(c) | set(other) if c.get(k) != other.get(k))
            raise MergeConflict(
                f"agent {run['agent']}: runs {other_key} and {key} ran the same episodes with other configurations "
                f"(they differ in {', '.join(differ)}); merging them under one name would mix two guardians. "
                f"Merge their directories separately"
            )
        seen[world] = (key, c)


def _merged_invocation(w: sqlite3.Connection, invocations: list[tuple[dict, str]], runs: dict) -> None:
    """One ``run`` invocation covering every input's last run: what ``rmm-bench report OUT`` shows."""
    first = invocations[0][0]
    config = _configuration(first["args"])
    for inv, name in invocations[1:]:
        if _configuration(inv["args"]) != config:
            differ = [k for k, a, b in zip(CONFIGURATION, config, _configuration(inv["args"]), strict=True) if a != b]
            raise MergeConflict(
                f"{name} ran another configuration than {invocations[0][1]} (it differs in {', '.join(differ)}): "
                f"one merged run holds one configuration; merge them into separate directories"
            )
    run_keys: dict[str, str] = {}
    for inv, _ in invocations:
        run_keys.update(inv["run_keys"])
    episodes = max(inv["episodes"] for inv, _ in invocations)
    args = dict(first["args"]) | {"shard": None, "agent": ",".join(run_keys)}
    have = {(k, e) for k, e in w.execute("SELECT run_key, episode FROM episodes WHERE outcome != 'error' OR "
                                            "COALESCE(error_kind, 'guardian') NOT IN (?, ?, ?, ?)", RETRIED_ERRORS)}  # fmt: skip
    lacking = sum(1 for key in run_keys.values() for e in range(episodes) if (key, e) not in have)
    status, message = (
        ("finished", None) if not lacking else ("failed", f"{lacking} episodes have no result in any part")
    )
    now = time.time()
    w.execute(
        "INSERT INTO invocations (created, kind, args, run_keys, episodes, status, pid, host, updated, message) "
        "VALUES (?, 'run', ?, ?, ?, ?, NULL, 'merge', ?, ?)",
        (now, json.dumps(args, sort_keys=True), json.dumps(run_keys), episodes, status, now, message),
    )


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench merge`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench merge",
        description="Join results directories (machines' shares of one run: --shard K/N, or any runs of one "
        "configuration) into --out: every episode stored twice is compared column by column (timing columns "
        "aside) and a difference refused; the inputs are read-only, its results.db is written atomically; "
        "then it holds the tables of the merged run (docs/machines.md).",
    )
    p.add_argument(
        "results_dirs", nargs="+", metavar="DIR", help="results directories (a run's --out) or their results.db to join"
    )
    p.add_argument("--out", type=Path, default=None, metavar="DIR", help="the new results directory they join into")
    return p


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench merge``; bad input and conflicts raise ``ValueError`` (exit 2 through the CLI)."""
    args = build_parser().parse_args(argv)
    if args.out is None:  # the form before --out took the first directory as the output: never guess
        raise ValueError(
            "merge: no --out; name the new results directory with --out DIR (rmm-bench merge DIR [DIR ...] "
            "--out DIR): the first directory is an input"
        )
    t0 = time.perf_counter()
    s = merge(args.out, args.results_dirs)
    print(
        f"merged {s.parts} parts into {s.out}: {s.episodes} episodes of {', '.join(s.agents)}, "
        f"{s.overlaps} stored in more than one part and equal in every compared column "
        f"({time.perf_counter() - t0:.1f} s); rmm-bench report {args.out} prints the table"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover - the CLI is rmm-bench merge
    sys.exit(cmd(sys.argv[1:]))
