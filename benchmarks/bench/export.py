"""``rmm-bench export``: a results database as one table in a documented, versioned schema.

Offers :data:`SCHEMA` (the columns of ``rmm-results/1`` in order, each with its type, unit and
meaning), :func:`export_frame`, :func:`write_export` and the command (:func:`build_parser`,
:func:`cmd`).

The file (Parquet or CSV) holds one row per stored episode, joined with its run's agent, env,
options, clock and seeds and its start's doomed flag, so results can be archived next to a
paper and read with pandas (or any Parquet or CSV reader) without this package.  Every row
carries the schema's name in its first column; a Parquet file also holds it in its metadata,
and a CSV file gets a ``.schema.json`` beside it with the column table.  The schema's version
changes whenever a column changes meaning or is removed; columns are only ever appended
within a version.  ``docs/comparing.md`` prints the column table.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from rmm_bench.names import did_you_mean
from rmm_bench.options import agent_option, refuse, results_dir
from rmm_bench.outputs import check_output, write_output
from rmm_bench.store import ResultsStore, results_database
from rmm_envs.starts import world_key

__all__ = ["OUTCOME_CODES", "SCHEMA", "SCHEMA_NAME", "build_parser", "cmd", "export_frame", "write_export"]

#: the schema's name and version, written in every row and the file's metadata
SCHEMA_NAME = "rmm-results/1"

#: outcome -> meaning
OUTCOME_CODES = {
    "goal": "reached the goal (success)",
    "collision": "hit an obstacle or wall, or left the world where that ends an episode",
    "timeout": "neither before the episode's time limit",
    "error": "no result of the agent: see error_kind and error",
}

#: the columns in order: (name, type, unit, meaning); types are pandas dtypes
SCHEMA: tuple[tuple[str, str, str, str], ...] = (
    ("schema", "string", "", f"the schema's name and version, {SCHEMA_NAME!r} in every row"),
    ("agent", "string", "", "the agent (guardian) name as run"),
    ("run_key", "string", "", "the run's key: a hash of everything that determines its episodes but the index"),
    ("env_id", "string", "", "the Gymnasium env id"),
    ("env_options", "string", "", "the env's options as JSON text (clock and time_accel included)"),
    ("clock", "string", "", "the non-blocking clock: 'fixed:MS' (reproducible), 'wall' or 'cpu'"),
    ("agent_options", "string", "", "the agent's constructor options as JSON text"),
    ("run_seed", "int64", "", "the run's --seed"),
    ("episode", "int64", "", "the episode's index in the run (0-based; what rmm-bench replay --episode takes)"),
    ("episode_seed", "int64", "", "the seed the env was reset with"),
    ("outcome", "string", "", "goal, collision, timeout or error (see the outcome codes)"),
    ("error_kind", "string", "", "for outcome error: guardian, timeout, lost_worker, input_changed or env"),
    ("steps", "Int64", "steps", "env steps taken"),
    ("active_steps", "Int64", "steps", "steps the guardian was in control"),
    ("sim_time", "float64", "s", "simulated time of the episode"),
    ("active_sim_time", "float64", "s", "simulated time the guardian was in control"),
    ("final_speed", "float64", "system units/s", "speed at the end (m/s on the quadrotor, world units/s on the cars)"),
    ("cum_reward", "float64", "", "the env's summed reward"),
    ("cost", "float64", "", "the env's summed info['cost'] (empty: the env reports none)"),
    ("qp_fallbacks", "Int64", "", "decisions where a QP-based guardian fell back (cbf)"),
    ("nan_states", "Int64", "", "steps whose state held NaN"),
    ("start", "string", "", "fingerprint of the episode's start (first observation, state and world), 16 hex"),
    ("doomed", "boolean", "", "the start was doomed (no control avoids a collision); empty: not assessed"),
    ("compute_time", "float64", "s", "the env clock's total agent time (timing: differs between machines)"),
    ("avg_compute_time", "float64", "s", "compute_time per step (Table I's policy compute time)"),
    ("decision_mean", "float64", "s", "mean measured time of one decision (timing)"),
    ("decision_std", "float64", "s", "its standard deviation (timing)"),
    ("decision_max", "float64", "s", "the longest decision (timing)"),
    ("precompute_time", "float64", "s", "the guardian's reset time, e.g. an HJ solve (timing)"),
    ("wall_time", "float64", "s", "the episode's wall-clock time (timing)"),
    ("guardian_stats", "string", "", "the guardian's own statistics as JSON text"),
    ("error", "string", "", "for outcome error: the message"),
    ("package_version", "string", "", "the rmm-envs version that ran it"),
    ("git_revision", "string", "", "the git revision of the checkout that ran it (empty when unknown)"),
)

_FROM_EPISODES = {
    "agent", "run_key", "episode", "outcome", "error_kind", "steps", "active_steps", "sim_time", "active_sim_time",
    "final_speed", "cum_reward", "cost", "qp_fallbacks", "nan_states", "start", "compute_time", "avg_compute_time",
    "decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time", "guardian_stats", "error",
}  # fmt: skip


def export_frame(path: str | Path, agents: list[str] | None = None) -> Any:
    """The episodes of the results at ``path`` (a results directory or ``results.db``, opened
    read-only) as a pandas DataFrame of :data:`SCHEMA`'s columns and types, ordered by agent,
    run and episode; ``agents``: only these (each must be stored)."""
    import pandas as pd

    store = ResultsStore(results_database(path, "export"), read_only=True)
    try:
        stored = [r[0] for r in store.db.execute("SELECT DISTINCT agent FROM runs ORDER BY agent")]
        for a in agents or []:
            if a not in stored:
                raise ValueError(
                    f"--agent {a}: not stored in {store.path}{did_you_mean(a, stored)} "
                    f"(expected one of: {', '.join(stored)})"
                )
        have = {r[1] for r in store.db.execute("PRAGMA table_info(episodes)")}
        cols = ", ".join(c if c in have else f"NULL AS {c}" for c in sorted(_FROM_EPISODES))
        episodes = pd.read_sql_query(f"SELECT {cols}, seed AS episode_seed FROM episodes", store.db)
        runs = {
            k: (json.loads(c), json.loads(p))
            for k, c, p in store.db.execute("SELECT run_key, config, provenance FROM runs")
        }
        doomed: dict[tuple[str, int], Any] = {}
        for key, (config, _) in runs.items():
            world = world_key(config["env_id"], config.get("env_kwargs", {}), int(config.get("seed", 0)))
            for e, s in store.starts(world).items():
                doomed[(key, e)] = s["doomed"]
    finally:
        store.close()
    if agents:
        episodes = episodes[episodes.agent.isin(agents)]
    episodes = episodes.sort_values(["agent", "run_key", "episode"], kind="stable").reset_index(drop=True)

    def of_run(field):
        return [field(*runs[k]) for k in episodes.run_key]

    episodes["schema"] = SCHEMA_NAME
    episodes["env_id"] = of_run(lambda c, p: c["env_id"])
    episodes["env_options"] = of_run(lambda c, p: json.dumps(c.get("env_kwargs", {}), sort_keys=True))
    episodes["clock"] = of_run(lambda c, p: str(c.get("env_kwargs", {}).get("clock", "wall")))
    episodes["agent_options"] = of_run(lambda c, p: json.dumps(c.get("agent_kwargs", {}), sort_keys=True))
    episodes["run_seed"] = of_run(lambda c, p: int(c.get("seed", 0)))
    episodes["package_version"] = of_run(lambda c, p: p.get("package_version"))
    episodes["git_revision"] = of_run(lambda c, p: p.get("git_revision"))
    episodes["doomed"] = [doomed.get((k, int(e))) for k, e in zip(episodes.run_key, episodes.episode, strict=True)]
    out = episodes[[name for name, *_ in SCHEMA]].copy()
    return out.astype({name: dtype for name, dtype, _, _ in SCHEMA})


def schema_description() -> dict:
    """The schema as JSON-ready data: name, columns (name, type, unit, meaning), outcome codes."""
    return {
        "schema": SCHEMA_NAME,
        "columns": [{"name": n, "type": t, "unit": u, "meaning": m} for n, t, u, m in SCHEMA],
        "outcomes": OUTCOME_CODES,
    }


def write_export(frame: Any, path: str | Path, fmt: str) -> list[Path]:
    """Write ``frame`` (:func:`export_frame`) to ``path`` as ``fmt`` (``parquet`` or ``csv``),
    atomically; a CSV also gets ``PATH.schema.json``.  Returns the files written."""
    path = Path(path)
    if fmt == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(frame, preserve_index=False)
        meta = dict(table.schema.metadata or {})
        meta[b"rmm_schema"] = json.dumps(schema_description()).encode()
        write_output(path, lambda tmp: pq.write_table(table.replace_schema_metadata(meta), tmp))
        return [path]
    if fmt == "csv":
        side = path.with_name(path.name + ".schema.json")
        write_output(path, lambda tmp: frame.to_csv(tmp, index=False))
        write_output(side, lambda tmp: tmp.write_text(json.dumps(schema_description(), indent=1) + "\n"))
        return [path, side]
    raise ValueError(f"--format {fmt!r}: expected parquet or csv")


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench export`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench export",
        description=f"Write the stored episodes as one table in the versioned schema {SCHEMA_NAME} "
        "(docs/comparing.md), readable without this package.  Opens the database read-only.",
        parents=[results_dir(), agent_option("one agent or a comma list (default: every stored one)")],
    )
    p.add_argument("--format", default="parquet", help="parquet (default) or csv")
    p.add_argument(
        "--table",
        type=Path,
        default=None,
        metavar="FILE",
        help="the file to write (default: DIR/results.parquet or DIR/results.csv)",
    )
    refuse(p, "--out", "write the table with --table FILE (--out is a directory in every command)")
    return p


def cmd(argv: list[str]) -> int:
    """Run ``rmm-bench export``; bad input raises ``ValueError`` (exit 2 through the CLI)."""
    args = build_parser().parse_args(argv)
    if args.format not in ("parquet", "csv"):
        raise ValueError(f"--format {args.format!r}: expected parquet or csv")
    agents = None if args.agent is None else [a.strip() for a in args.agent.split(",") if a.strip()]
    source = Path(args.results_dir)
    folder = source if source.is_dir() else source.parent
    out = args.table or folder / f"results.{args.format}"
    db = results_database(source, "export")
    check_output(out, "--table", reads=[db])  # before anything is read: never over the database
    if args.format == "csv":
        check_output(out.with_name(out.name + ".schema.json"), "--table (its .schema.json)", reads=[db])
    frame = export_frame(source, agents)
    for f in write_export(frame, out, args.format):
        print(f"wrote {f}", file=sys.stderr)
    print(f"{len(frame)} episodes of {frame.agent.nunique()} agents in {SCHEMA_NAME}", file=sys.stderr)
    return 0
