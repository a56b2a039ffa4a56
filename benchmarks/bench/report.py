"""``rmm-bench report`` and the tables of every run: Table I (Markdown, CSV, LaTeX) and figures (PNG).

Tables are built from the stored rows alone: a name read from the database (a guardian
``module:Class``, an env id) is never imported.  For runs stored before the guardian's
observation type and the env's obstacle count were recorded, only built-in guardian names and
this package's env ids are looked up.

This module gathers the rows (:func:`table_rows`), picks the recorded commands a report covers
(:func:`newest_configuration`: by default every run recorded under the newest run's
configuration) and writes them (:func:`write_report`, :func:`cmd_report`); the text of the
tables is :mod:`rmm_bench.report_tables`, the paper's rows :mod:`rmm_bench.report_paper`, the
figures :mod:`rmm_bench.report_figures`, the results page :mod:`rmm_bench.html`.
"""

from __future__ import annotations

import json
import os
import sys
from collections import Counter
from pathlib import Path

from rmm_bench.config import parse_shard, shard_episodes
from rmm_bench.html import write_page
from rmm_bench.metrics import aggregate, avoidable_collisions
from rmm_bench.outputs import check_output
from rmm_bench.report_figures import plot_latency, plot_outcomes
from rmm_bench.report_paper import NOT_REPORTED, PAPER_ENVS, PAPER_LABEL, PAPER_TABLE_I, format_paper_table
from rmm_bench.report_tables import AVOIDABLE_HEADER, COLUMNS, WILSON_MARK, format_tables, merge_csv, spread_note
from rmm_bench.store import RETRIED_ERRORS, ResultsStore
from rmm_envs import ENV_IDS
from rmm_envs.catalog import current_id
from rmm_envs.starts import world_key
from rmm_guardians.registry import BUILTIN, load_guardian_class

__all__ = [
    "AVOIDABLE_HEADER",
    "COLUMNS",
    "CONFIGURATION",
    "NOT_REPORTED",
    "PAPER_ENVS",
    "PAPER_LABEL",
    "PAPER_TABLE_I",
    "WILSON_MARK",
    "cmd_report",
    "format_paper_table",
    "format_tables",
    "guardian_counters",
    "newest_configuration",
    "plot_latency",
    "plot_outcomes",
    "spread_note",
    "table_rows",
    "write_report",
]


# ------------------------------------------------------------------ the report command
def _legacy_meta(agent: str, config: dict) -> dict:
    """Observation type and obstacle count for runs stored before they were recorded: only
    built-in guardian names and this package's envs are looked up (our own modules); a name
    from the database is never imported."""
    meta = {"observation": "?", "n_obstacles": "?"}
    if agent in BUILTIN:
        try:
            meta["observation"] = getattr(load_guardian_class(agent), "observation_type", "?")
        except Exception:
            pass
    env_id = current_id(str(config.get("env_id")))  # a former id, read back under today's
    if env_id in ENV_IDS:
        import gymnasium as gym

        env = gym.make(env_id)
        meta["n_obstacles"] = getattr(env.unwrapped, "n_obstacles", "?")
        env.close()
    return meta


def table_rows(
    store: ResultsStore, run_keys: dict[str, str], episodes, batch_size: int = 64, requested: dict | None = None
) -> list[dict]:
    """Aggregate rows from the stored rows alone; ``episodes`` is one count for every agent or a
    dict per agent; ``requested``: per agent, how many of them the command owed when fewer (a
    ``--shard``'s share).  Each row also says how many episodes have a result (``with_result``:
    all stored but those over the time limit or lost with their worker)."""
    rows = []
    for agent, key in run_keys.items():
        n = episodes[agent] if isinstance(episodes, dict) else episodes
        eps = store.episodes(key, n)
        run = store.run_config(key)
        meta = run["provenance"].get("guardian") or _legacy_meta(agent, run["config"])
        agg = aggregate(eps, batch_size) | avoidable_collisions(eps, _doomed_flags(store, run["config"]), batch_size)
        missing = Counter(
            _missing_reason(e) for e in eps if e["outcome"] == "error" and e.get("error_kind") in RETRIED_ERRORS
        )
        with_result = len(eps) - sum(missing.values())
        rows.append(
            {
                "agent": agent,
                "obs": meta.get("observation", "?"),
                "n_obst": meta.get("n_obstacles", "?"),
                "requested": (requested or {}).get(agent, n),
                "with_result": with_result,
                "missing": dict(missing),
                "counters": guardian_counters(eps),
                **agg,
            }
        )
    return rows


def guardian_counters(episodes: list[dict]) -> dict[str, float]:
    """The guardian's own statistics (its ``stats()`` dict, stored per episode as
    ``guardian_stats``) summed over ``episodes``, key by key in the order it reported them:
    built-in (``cbf``'s ``qp_solves``) or a third-party guardian's alike."""
    totals: dict[str, float] = {}
    for e in episodes:
        try:
            stats = json.loads(e.get("guardian_stats") or "{}")
        except ValueError:
            continue
        for k, v in stats.items() if isinstance(stats, dict) else ():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                totals[k] = totals.get(k, 0) + v
    return totals


def _doomed_flags(store: ResultsStore, config: dict) -> dict[int, bool | None]:
    """Episode -> doomed flag of the starts of a run's world (empty before starts were stored)."""
    key = world_key(config["env_id"], config.get("env_kwargs", {}), int(config.get("seed", 0)))
    return {e: s["doomed"] for e, s in store.starts(key).items()}


#: why an episode whose error_kind is in RETRIED_ERRORS has no result, as the INCOMPLETE line says it
_MISSING = {
    "timeout": "stored over the time limit",
    "lost_worker": "lost with their worker",
    "input_changed": "not run as a file they read changed",
}


def _missing_reason(e: dict) -> str:
    error_kind = e.get("error_kind")
    if error_kind == "env":
        unmade = (e.get("error") or "").startswith("EnvUnavailable")
        return "unable to make the env in their worker" if unmade else "ended by an error the env raised"
    return _MISSING.get(error_kind or "", f"ended in an error of kind {error_kind}")


def _completeness(rows: list[dict], invs: list[dict]) -> str:
    """'' when every agent has a result for every requested episode, else what is missing and why."""
    short = [r for r in rows if r["with_result"] < r["requested"]]
    if not short:
        return ""
    have = ", ".join(f"{r['agent']} {r['with_result']} of {r['requested']}" for r in short)
    why = []
    missing: Counter[str] = Counter()
    for r in short:
        missing.update(r.get("missing", {}))
    if missing:
        why.append(", ".join(f"{n} {reason}" for reason, n in sorted(missing.items(), key=lambda kv: -kv[1])))
    for inv in invs:
        state = inv.get("state", inv["status"])
        if state == "stale":
            why.append(f"invocation {inv['id']} was killed: it is marked running but its process {inv['pid']} is gone")
        elif state == "running":
            why.append(f"invocation {inv['id']} is still running (process {inv['pid']} on {inv['host']})")
        elif state in ("interrupted", "failed"):
            msg = inv.get("message") or ""
            detail = f": {msg}" if msg and "ended without a result" not in msg else ""
            why.append(f"invocation {inv['id']} {state}{detail}")
    return (
        f"INCOMPLETE: episodes with a result: {have}"
        + (f" ({'; '.join(why)})" if why else "")
        + ". Rerun the same command to finish; the table covers the stored episodes only.\n"
    )


#: What a table's header names: runs that differ in any of these are never merged under one header.
CONFIGURATION = ("env", "clock", "time_accel", "base_step", "seed")


def _configuration(inv: dict) -> tuple:
    return tuple(inv["args"].get(k) for k in CONFIGURATION)


def _today(inv: dict) -> dict:
    """``inv`` with a former env id read as today's: a run recorded under it and its rerun are one
    configuration."""
    env = inv["args"].get("env")
    return inv | {"args": inv["args"] | {"env": current_id(env)}} if isinstance(env, str) else inv


def newest_configuration(store: ResultsStore) -> list[dict]:
    """The recorded runs ``rmm-bench report DIR`` covers by default: every ``run`` invocation
    recorded under the configuration (:data:`CONFIGURATION`) of the newest one, oldest first, so
    that later ones win per agent (an agent keeps its place in the table); an agent whose run is
    no longer stored and that no later invocation reran is left out.  ``LookupError`` when no
    run is recorded."""
    newest = _today(store.invocation(None, command="run"))
    ids = [i for (i,) in store.db.execute("SELECT id FROM invocations WHERE kind = 'run' ORDER BY id")]
    stored = {k for (k,) in store.db.execute("SELECT run_key FROM runs")}
    invs = [inv for inv in map(_today, map(store.invocation, ids)) if _configuration(inv) == _configuration(newest)]
    out = []
    for n, inv in enumerate(invs):
        later = {a for other in invs[n + 1 :] for a in other["run_keys"]}
        keys = {a: k for a, k in inv["run_keys"].items() if k in stored or a in later or inv is invs[-1]}
        if keys:
            out.append(inv | {"run_keys": keys})
    return out


def _header(args: dict) -> str:
    return f"{args.get('env')}, clock {args.get('clock')}, time accel {args.get('time_accel')}, seed {args.get('seed')}"


def _shard_note(shards: set[str], requested: dict[str, int]) -> str:
    """', shard K/N: M of them' for a sharded command (``rmm-bench merge`` joins the shards)."""
    if not shards:
        return ""
    counts = "/".join(map(str, sorted(set(requested.values()))))
    return f", shard {', '.join(sorted(shards))}: {counts} of them (rmm-bench merge joins the shards)"


def write_report(
    store: ResultsStore,
    out: Path,
    invs: list[dict] | dict,
    batch_size: int = 64,
    quiet: bool = False,
    figure: bool = True,
    sections: list[dict] | None = None,
    write_files: bool = True,
) -> str:
    """Tables and figures for one recorded command, or several merged (later ones win per agent);
    ``write_files=False`` only returns (and prints) them, for a results directory that is read-only;
    ``figure=False`` writes the tables only and removes an ``outcomes.png`` left from an earlier
    run, which would not match them.  ``sections``, when given, receives one dict per
    configuration (``title``, ``args``, ``run_keys``, ``rows``, ``md``, ``notes``: the
    completeness line, ``batch_size``, ``measured``: a fixed clock, ``invocations``: their ids),
    what the results page (:mod:`rmm_bench.html`) lays out.

    Commands run under different configurations (env, clock, time acceleration, base step,
    seed) are never put under one header: each configuration gets its own header and table,
    in the printed report and in ``table_I.md``/``.tex``, the CSV gets the configuration's
    columns, and the figure labels each agent with its table's number."""
    invs = [_today(inv) for inv in ([invs] if isinstance(invs, dict) else invs)]
    groups: dict[tuple, list[dict]] = {}
    for inv in invs:
        groups.setdefault(_configuration(inv), []).append(inv)
    mixed = len(groups) > 1
    texts, md, tex, csv_parts, figure_rows = [], [], [], [], []
    for number, group in enumerate(groups.values(), 1):
        run_keys, episodes, requested = {}, {}, {}
        shards = set()
        for inv in group:
            shard = inv["args"].get("shard")
            if shard:
                shards.add(shard)
            for agent, key in inv["run_keys"].items():
                run_keys[agent], episodes[agent] = key, inv["episodes"]
                requested[agent] = len(shard_episodes(inv["episodes"], parse_shard(shard) if shard else None))
        rows = table_rows(store, run_keys, episodes, batch_size, requested)
        measured = str(group[-1]["args"].get("clock", "")).strip().lower().startswith("fixed")
        tables = format_tables(rows, batch_size, measured)
        args = group[-1]["args"]
        label = f"[{number}] " if mixed else ""
        md.append(f"{label}{_header(args)}\n\n{tables['md']}" if mixed else tables["md"])
        tex.append(f"% {label}{_header(args)}\n{tables['tex']}" if mixed else tables["tex"])
        csv_parts.append((args, tables["csv"]))
        figure_rows += [r | {"agent": f"{r['agent']} [{number}]"} for r in rows] if mixed else rows
        counts = sorted(set(episodes.values()))
        if sections is not None:
            sections.append(
                {
                    "title": f"Table I{' ' + label.strip() if mixed else ''}: {_header(args)}, "
                    f"{'/'.join(map(str, counts))} episodes requested per agent{_shard_note(shards, requested)}",
                    "args": args,
                    "run_keys": dict(run_keys),
                    "rows": rows,
                    "md": tables["md"],
                    "notes": _completeness(rows, group),
                    "batch_size": batch_size,
                    "measured": measured,
                    "invocations": [inv.get("id") for inv in group],
                }
            )
        text = (
            f"Table I{' ' + label.strip() if mixed else ''}: {_header(args)}, {'/'.join(map(str, counts))} episodes "
            f"requested per agent{_shard_note(shards, requested)} (results in {out})\n"
            f"{_completeness(rows, group)}\n{tables['md']}"
        )
        paper = format_paper_table(run_keys)
        if paper and args.get("env") in PAPER_ENVS:  # the paper evaluated guardians on Dubins4D only
            text += (
                "\nFor comparison, the paper's Table I rows for these agents: the paper's own implementations "
                f"and LRMM model, not the guardians run here:\n\n{paper}"
            )
        texts.append(text)
    try:
        if write_files:
            (out / "table_I.md").write_text("\n".join(md))
            (out / "table_I.csv").write_text(merge_csv(csv_parts, CONFIGURATION) if mixed else csv_parts[0][1])
            (out / "table_I.tex").write_text("\n".join(tex))
            if figure:
                plot_outcomes(
                    figure_rows,
                    out / "outcomes.png",
                    batch_size,
                    any(
                        str(g[-1]["args"].get("clock", "")).strip().lower().startswith("fixed") for g in groups.values()
                    ),
                )
            else:
                (out / "outcomes.png").unlink(missing_ok=True)
    except OSError as e:  # a full disk names no file: name the directory (the CLI prints one line)
        if e.filename is None:
            raise OSError(e.errno, e.strerror or str(e), str(out)) from None
        raise
    text = "\n".join(texts)
    if mixed:
        text = (
            f"{len(groups)} configurations, one table each (they differ in "
            f"{', '.join(c for i, c in enumerate(CONFIGURATION) if len({g[i] for g in groups}) > 1)}):\n\n{text}"
        )
    if not quiet:
        print(text)
    return text


def cmd_report(request) -> int:
    """``rmm-bench report``; ``request`` is an :class:`rmm_bench.results_args.ReportRequest`."""
    if not (request.dir / "results.db").is_file():
        print(f"rmm-bench report: error: no results.db in {request.dir}", file=sys.stderr)
        return 2
    if request.html is not None:  # before anything is written: never over the database it reads
        check_output(request.html, "--html", reads=[request.dir / "results.db"])
    store = ResultsStore(request.dir / "results.db", read_only=True)  # a report never changes the database
    try:
        if request.invocations:
            invs = [store.invocation(i) for i in request.invocations]
        else:
            try:
                invs = newest_configuration(store)
            except LookupError:
                sweep = request.dir / "disturbance_sweep.md"
                if sweep.is_file():  # a disturbance sweep only: its table, and a page of it
                    print(sweep.read_text(encoding="utf-8"))
                    if request.html is not None:
                        print(f"wrote {write_page(request.html, request.dir, store, [])}")
                    return 0
                try:
                    store.invocation(None, command="sweep")
                except LookupError:
                    raise LookupError(f"no benchmark run recorded in {store.path}") from None
                raise LookupError(
                    f"{request.dir} holds a latency sweep, not a benchmark run: rerun its "
                    "`rmm-bench sweep` command with the same --out, which reads the stored "
                    "episodes back and rewrites latency_sweep.md and .png (the .png not with "
                    "--no-figure)"
                ) from None
        sections: list[dict] = []
        writable = os.access(request.dir, os.W_OK | os.X_OK)
        write_report(store, request.dir, invs, request.batch_size, sections=sections, write_files=writable)
        if not writable:
            print(
                f"rmm-bench report: {request.dir} is read-only: the table is printed above; table_I.md/.csv/.tex "
                "and outcomes.png there were not rewritten",
                file=sys.stderr,
            )
        if request.html is not None:
            path = write_page(request.html, request.dir, store, sections)
            print(f"wrote {path}")
    finally:
        store.close()
    return 0
