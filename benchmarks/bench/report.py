"""``rmm-bench report`` and the tables of every run: Table I (Markdown, CSV, LaTeX) and figures (PNG).

Tables are built from the stored rows alone: a name read from the database (a guardian
``module:Class``, an env id) is never imported.  For runs stored before the guardian's
observation type and the env's obstacle count were recorded, only built-in guardian names and
this package's env ids are looked up.
"""

from __future__ import annotations

import csv
import io
import math
import os
import sys
from collections import Counter
from pathlib import Path

from rmm_bench.config import parse_shard, shard_episodes
from rmm_bench.metrics import aggregate, avoidable_collisions
from rmm_bench.names import md_cell, tex_cell
from rmm_bench.outputs import check_output
from rmm_bench.store import RETRIED_ERRORS, ResultsStore
from rmm_envs.catalog import current_id

__all__ = [
    "PAPER_LABEL",
    "PAPER_TABLE_I",
    "cmd_report",
    "format_paper_table",
    "format_tables",
    "plot_latency",
    "plot_outcomes",
    "table_rows",
    "write_report",
]

#: The envs the paper's Table I describes (it evaluated guardians on Dubins4D only); the report
#: prints the paper's rows next to a run on one of them.
PAPER_ENVS = ("Dubins4DParallel-v0", "Dubins4DGuarded-v0")
#: How the report labels the paper's rows, after the agent's name: the paper's own implementations
#: and model, which a run here does not reproduce exactly (our ``lrmm`` is not the paper's LRMM).
PAPER_LABEL = "paper, ICRA 2023"
#: The paper's Table I figures (2048 episodes per agent; its HJ row used single-obstacle envs), per
#: agent: ``(mean, std)``, ``std`` None where the paper printed the mean alone, or the paper's text
#: where it printed a bound or an approximation.  The paper reported no errors, QP fallbacks or
#: measured decision times: the report shows ``—`` for those.
PAPER_TABLE_I: dict[str, dict] = {
    "lrmm": {
        "obs": "local",
        "n_obst": 5,
        "compute_ms": (2.4, 5.0),
        "goal": (45.3, 7.3),
        "collision": (29.7, 5.6),
        "timeout": (25.0, 4.8),
        "intervention": (30.7, 32.5),
    },
    "cbf": {
        "obs": "global",
        "n_obst": 5,
        "compute_ms": (52.9, 41.2),
        "goal": (46.2, 5.9),
        "collision": (35.1, 5.2),
        "timeout": (18.8, 3.8),
        "intervention": (32.8, 39.4),
    },
    "random": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (1.4, 2.7),
        "goal": (27.1, 6.9),
        "collision": (68.4, 5.9),
        "timeout": (4.5, 2.9),
        "intervention": "~50",
    },
    "inactive": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (1.0, 2.3),
        "goal": (44.4, 7.4),
        "collision": (55.4, 7.3),
        "timeout": (0.1, 0.5),
        "intervention": (0.0, None),
    },
    "brakes": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (0.3, 0.7),
        "goal": (0.6, 0.9),
        "collision": (9.0, 3.8),
        "timeout": (90.4, 3.7),
        "intervention": (100.0, None),
    },
    "hj": {
        "obs": "global",
        "n_obst": 1,
        "compute_ms": (344.0, 850.0),
        "goal": (54.0, 5.2),
        "collision": (46.0, 5.3),
        "timeout": (0.0, 0.3),
        "intervention": "<1.0",
    },
}
#: The paper's episodes per agent.
PAPER_EPISODES = 2048
#: What the paper reported nothing for.
NOT_REPORTED = "—"

COLUMNS = [
    ("compute_ms", "Policy compute time [ms]"),
    ("goal", "Success rate [% eps]"),
    ("collision", "Collision rate [% eps]"),
    ("timeout", "Timeout rate [% eps]"),
    ("intervention", "Intervention rate [% sim time]"),
]


def _pm(v, digits=1) -> str:
    m, s = v
    if m is None or (isinstance(m, float) and math.isnan(m)):
        return "n/a"
    if s is None or (isinstance(s, float) and math.isnan(s)):
        return f"{m:.{digits}f}"
    return f"{m:.{digits}f} ± {s:.{digits}f}"


#: Table I's column of collisions from avoidable starts (shown where every start was assessed)
AVOIDABLE_HEADER = "Collision rate, avoidable starts [% of them]"

#: The mark on rates whose spread is the Wilson interval (fewer than two batches).
WILSON_MARK = "†"


def _digits(ms: float) -> int:
    return 3 if ms < 0.1 else 2 if ms < 10 else 1


def spread_note(rows: list[dict], batch_size: int) -> str:
    """What the ± of the rates means in these rows (a line under the table)."""
    note = f"Rates: mean ± std over batches of {batch_size} episodes (the paper's)"
    if any(r.get("rate_spread") == "wilson95" for r in rows):
        note += (
            f"; {WILSON_MARK}: fewer than two batches, so the rate is followed by its 95% Wilson score "
            "interval over the episodes, [low, high]"
        )
    return note + "."


def _rate(r: dict, key: str) -> str:
    """A rate's cell: ``mean ± std`` over batches, or ``mean [low, high]†`` (the Wilson interval)."""
    ci = r.get(f"{key}_ci")
    spread = r.get(f"{key}_spread", r.get("rate_spread"))
    if spread != "wilson95" or ci is None or math.isnan(ci[0]) or math.isnan(r[key][0]):
        return _pm(r[key])
    return f"{r[key][0]:.1f} [{ci[0]:.1f}, {ci[1]:.1f}]{WILSON_MARK}"


def format_tables(rows: list[dict], batch_size: int = 64, measured: bool = False) -> dict[str, str]:
    """``rows``: dicts with agent, obs, n_obst, episodes, errors and the aggregate stats.
    ``measured``: add the guardian's measured decision time (``decision_ms``) beside the
    compute time the clock charged (under a fixed clock the two differ)."""
    header = ["Agent", "Observation", "Obstacles", "Episodes"] + [c[1] for c in COLUMNS] + ["Errors", "QP fallbacks"]
    if measured:
        header.insert(5, "Measured decision time [ms]")
    assessed = bool(rows) and all("avoidable_collision" in r for r in rows)  # every start's doomed flag stored
    if assessed:
        at = header.index("Collision rate [% eps]") + 1
        header[at:at] = [AVOIDABLE_HEADER, "Doomed starts"]
    body = []
    for r in rows:
        n_obst = (
            "-" if isinstance(r["n_obst"], int) and r["n_obst"] < 0 else str(r["n_obst"])
        )  # -1: the env counts none
        cells = [r["agent"], r["obs"], n_obst, str(r["episodes"]), _pm(r["compute_ms"], _digits(r["compute_ms"][0]))]
        if measured:
            dec = r.get("decision_ms", (float("nan"), float("nan")))
            cells.append(_pm(dec, _digits(dec[0])) if not math.isnan(dec[0]) else "n/a")
        rates = [_rate(r, k) for k, _ in COLUMNS[1:]]
        if assessed:
            rates[2:2] = [_rate(r, "avoidable_collision"), str(r["doomed_starts"])]
        cells += rates
        body.append(cells + [str(r["errors"]), str(r["qp_fallbacks"])])
    md = "| " + " | ".join(header) + " |\n|" + "|".join("---" for _ in header) + "|\n"
    md += "".join("| " + " | ".join(map(md_cell, b)) + " |\n" for b in body)  # a name may hold a | or a line break
    md += "\n" + spread_note(rows, batch_size) + "\n"
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(
        [
            "agent",
            "observation",
            "obstacles",
            "episodes",
            "compute_ms_mean",
            "compute_ms_std",
            "success_mean",
            "success_std",
            "collision_mean",
            "collision_std",
            "timeout_mean",
            "timeout_std",
            "intervention_mean",
            "intervention_std",
            "errors",
            "qp_fallbacks",
            "precompute_s_mean",
            "decision_ms_mean",
            "decision_ms_std",
            "rate_spread",
        ]
        + (["avoidable_collision_mean", "avoidable_collision_std", "doomed_starts"] if assessed else [])
    )
    for r in rows:
        w.writerow(
            [
                r["agent"],
                r["obs"],
                r["n_obst"],
                r["episodes"],
                *r["compute_ms"],
                *r["goal"],
                *r["collision"],
                *r["timeout"],
                *r["intervention"],
                r["errors"],
                r["qp_fallbacks"],
                r["precompute_s"][0],
                *r.get("decision_ms", (float("nan"), float("nan"))),
                r.get("rate_spread", "batches"),
            ]
            + ([*r["avoidable_collision"], r["doomed_starts"]] if assessed else [])
        )
    cols = "llcr" + "r" * (len(header) - 6)
    tex = f"\\begin{{tabular}}{{{cols}}}\n" + " & ".join(map(tex_cell, header[:-2])) + " \\\\ \\hline\n"
    tex += (
        "".join(
            " & ".join(tex_cell(c).replace("±", "$\\pm$").replace(WILSON_MARK, "$^\\dagger$") for c in b[:-2])
            + " \\\\\n"
            for b in body
        )
        + "\\end{tabular}\n"
    )
    return {"md": md, "csv": buf.getvalue(), "tex": tex}


def _paper_cell(v) -> str:
    """A figure of the paper's table as the paper printed it: ``mean ± std`` (one decimal), the
    mean alone (``0``, ``100``), or its text (a bound, an approximation)."""
    if isinstance(v, str):
        return v
    m, s = v
    return f"{m:g}" if s is None else f"{m:.1f} ± {s:.1f}"


def paper_agent(agent: str) -> str | None:
    """The paper's row for our ``agent`` (itself, or the ``-paper`` preset of one), else None."""
    base = agent.removesuffix("-paper")
    return base if base in PAPER_TABLE_I else None


def format_paper_table(agents) -> str:
    """The paper's Table I rows for ``agents`` (names of ours: each built-in, or its ``-paper``
    preset, maps to the paper's row of that name), in Markdown with the columns of our table.
    Each row is labelled as the paper's (:data:`PAPER_LABEL`): the paper's implementations and
    model, not ours.  ``—`` where the paper reported nothing (errors, QP fallbacks).  ``""`` when
    no agent has a paper row."""
    names = list(dict.fromkeys(a for a in map(paper_agent, agents) if a is not None))
    if not names:
        return ""
    columns = [c[1] for c in COLUMNS[:-1]] + ["Intervention rate [% steps]"]  # the paper's unit
    header = ["Agent", "Observation", "Obstacles", "Episodes"] + columns + ["Errors", "QP fallbacks"]
    md = "| " + " | ".join(header) + " |\n|" + "|".join("---" for _ in header) + "|\n"
    for a in names:
        p = PAPER_TABLE_I[a]
        cells = [f"{a} ({PAPER_LABEL})", p["obs"], str(p["n_obst"]), str(PAPER_EPISODES)]
        cells += [_paper_cell(p[k]) for k, _ in COLUMNS] + [NOT_REPORTED, NOT_REPORTED]
        md += "| " + " | ".join(cells) + " |\n"
    return md + (
        f"\nThe paper's figures as it printed them: {PAPER_EPISODES} episodes per agent, its HJ row on "
        "single-obstacle envs, its intervention rate in % of steps (ours: % of simulated time); "
        f"{NOT_REPORTED}: the paper gave no figure.\n"
    )


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_outcomes(rows: list[dict], path: Path, batch_size: int = 64, measured: bool = False) -> Path:
    """Outcome rates per agent, and collisions against compute time: the time the clock charged,
    or with ``measured`` (a fixed clock, which charges every agent the same) the guardian's
    measured decision time."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    names = [r["agent"] for r in rows]
    x = range(len(rows))
    width = 0.26
    for i, (key, colour) in enumerate([("goal", "tab:green"), ("collision", "tab:red"), ("timeout", "tab:gray")]):
        axes[0].bar(
            [j + (i - 1) * width for j in x],
            [r[key][0] for r in rows],
            width,
            yerr=[0 if math.isnan(r[key][1]) else r[key][1] for r in rows],
            color=colour,
            capsize=3,
            label=key,
        )
    # long names (``lrmm-paper``, ``cbf-paper``) run into each other when set level
    axes[0].set_xticks(list(x), names, rotation=30, ha="right")
    wilson = any(r.get("rate_spread") == "wilson95" for r in rows)
    axes[0].set_ylabel(
        f"% of episodes (mean ± std over batches of {batch_size}"
        + ("; 95% Wilson where < 2 batches)" if wilson else ")")
    )
    axes[0].set_ylim(0, 118)  # headroom above 100 % so the legend covers no bar
    axes[0].legend(loc="upper center", ncols=3, fontsize="small")
    axes[0].set_title("Outcomes")
    key = "decision_ms" if measured else "compute_ms"
    for i, r in enumerate(rows):
        x_ms = r.get(key, (float("nan"),))[0]
        if math.isnan(x_ms):
            continue
        axes[1].errorbar(max(x_ms, 1e-4), r["collision"][0], yerr=r["collision"][1], fmt="o", capsize=3)
        # labels of nearby points are staggered vertically so that they do not overlap
        axes[1].annotate(
            r["agent"], (max(x_ms, 1e-4), r["collision"][0]), textcoords="offset points", xytext=(5, 5 + 11 * (i % 3))
        )
    axes[1].set_xscale("log")
    axes[1].margins(x=0.2)  # room for the rightmost point's label inside the axes
    from matplotlib.ticker import NullFormatter

    axes[1].xaxis.set_minor_formatter(NullFormatter())  # minor labels collide on short decades
    axes[1].set_xlabel(
        "measured decision time [ms] (log)\n(the fixed clock charged every agent the same)"
        if measured
        else "policy compute time per step [ms] (log)"
    )
    axes[1].set_ylabel("collision rate [% episodes]")
    axes[1].set_title("Compute time vs collisions")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_latency(series: dict[str, list[tuple[float, float, float]]], path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for agent, pts in series.items():
        pts = sorted(pts)
        ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts], marker="o", capsize=3, label=agent
        )
    ax.set_xlabel("added decision latency [ms of wall time]")
    ax.set_ylabel("collision rate [% episodes]")
    ax.set_title("Compute time costs safety")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# ------------------------------------------------------------------ the report command
def _legacy_meta(agent: str, config: dict) -> dict:
    """Observation type and obstacle count for runs stored before they were recorded: only
    built-in guardian names and this package's envs are looked up (our own modules); a name
    from the database is never imported."""
    from rmm_envs import ENV_IDS
    from rmm_guardians.registry import BUILTIN, load_guardian_class

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
                **agg,
            }
        )
    return rows


def _doomed_flags(store: ResultsStore, config: dict) -> dict[int, bool | None]:
    """Episode -> doomed flag of the starts of a run's world (empty before starts were stored)."""
    from rmm_envs.starts import world_key

    key = world_key(config["env_id"], config.get("env_kwargs", {}), int(config.get("seed", 0)))
    return {e: s["doomed"] for e, s in store.starts(key).items()}


#: why an episode of a kind in RETRIED_ERRORS has no result, as the INCOMPLETE line says it
_MISSING = {
    "timeout": "stored over the time limit",
    "lost_worker": "lost with their worker",
    "input_changed": "not run as a file they read changed",
}


def _missing_reason(e: dict) -> str:
    kind = e.get("error_kind")
    if kind == "env":
        unmade = (e.get("error") or "").startswith("EnvUnavailable")
        return "unable to make the env in their worker" if unmade else "ended by an error the env raised"
    return _MISSING.get(kind or "", f"ended in an error of kind {kind}")


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


def _header(args: dict) -> str:
    return f"{args.get('env')}, clock {args.get('clock')}, time accel {args.get('time_accel')}, seed {args.get('seed')}"


def _merge_csv(parts: list[tuple[dict, str]]) -> str:
    """The CSV tables of several configurations in one, each row led by its configuration's columns."""
    buf = io.StringIO()
    w = csv.writer(buf)
    for k, (args, text) in enumerate(parts):
        lines = list(csv.reader(io.StringIO(text)))
        if k == 0:
            w.writerow(list(CONFIGURATION) + lines[0])
        for line in lines[1:]:
            w.writerow([args.get(c) for c in CONFIGURATION] + line)
    return buf.getvalue()


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
    completeness line), what the results page (:mod:`rmm_bench.html`) lays out.

    Commands run under different configurations (env, clock, time acceleration, base step,
    seed) are never put under one header: each configuration gets its own header and table,
    in the printed report and in ``table_I.md``/``.tex``, the CSV gets the configuration's
    columns, and the figure labels each agent with its table's number."""
    invs = [invs] if isinstance(invs, dict) else list(invs)
    # a former env id is today's id: a run recorded under it and its rerun are one configuration
    invs = [
        inv | {"args": inv["args"] | {"env": current_id(inv["args"]["env"])}}
        if isinstance(inv["args"].get("env"), str)
        else inv
        for inv in invs
    ]
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
            (out / "table_I.csv").write_text(_merge_csv(csv_parts) if mixed else csv_parts[0][1])
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
    """``rmm-bench report``; ``request`` is an :class:`rmm_bench.args.ReportRequest`."""
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
                invs = [store.invocation(None, kind="run")]
            except LookupError:
                try:
                    store.invocation(None, kind="sweep")
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
            from rmm_bench.html import write_page

            path = write_page(request.html, request.dir, store, sections)
            print(f"wrote {path}")
    finally:
        store.close()
    return 0
