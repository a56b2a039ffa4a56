"""Table I as text: Markdown, CSV and LaTeX from the aggregated rows (:func:`format_tables`).

Offers :data:`COLUMNS`, :data:`AVOIDABLE_HEADER`, :data:`WILSON_MARK`, :func:`format_tables`,
:func:`counter_columns`, :func:`merge_csv` and :func:`spread_note`.  A row is what
:func:`rmm_bench.report.table_rows` returns: the agent, its observation and obstacle count, the
statistics of :func:`rmm_bench.metrics.aggregate` and ``counters``, the sums over its episodes of
the guardian's own ``stats()`` (built-in or third-party), which the CSV carries as ``stats.NAME``
columns (as :func:`rmm_bench.load_results` names them with ``expand_stats``).
"""

from __future__ import annotations

import csv
import io
import math

from rmm_bench.names import md_cell, tex_cell

__all__ = [
    "AVOIDABLE_HEADER",
    "COLUMNS",
    "WILSON_MARK",
    "counter_columns",
    "counter_text",
    "format_tables",
    "merge_csv",
    "spread_note",
]

COLUMNS = [
    ("compute_ms", "Policy compute time [ms]"),
    ("goal", "Success rate [% eps]"),
    ("collision", "Collision rate [% eps]"),
    ("timeout", "Timeout rate [% eps]"),
    ("intervention", "Intervention rate [% sim time]"),
]

#: Table I's column of collisions from avoidable starts (shown where every start was assessed)
AVOIDABLE_HEADER = "Collision rate, avoidable starts [% of them]"

#: The mark on rates whose spread is the Wilson interval (fewer than two batches).
WILSON_MARK = "†"

#: the CSV's prefix of a guardian counter's column (``stats.qp_solves``)
STATS_PREFIX = "stats."


def _pm(v, digits=1) -> str:
    m, s = v
    if m is None or (isinstance(m, float) and math.isnan(m)):
        return "n/a"
    if s is None or (isinstance(s, float) and math.isnan(s)):
        return f"{m:.{digits}f}"
    return f"{m:.{digits}f} ± {s:.{digits}f}"


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


def counter_columns(rows: list[dict]) -> list[str]:
    """The guardian counters any of ``rows`` reported, in order of first appearance."""
    return list(dict.fromkeys(k for r in rows for k in r.get("counters", {})))


def counter_text(value) -> str:
    """A counter's total as a cell: an integer as one, else 4 significant digits; ``""`` when none."""
    if value is None:
        return ""
    if float(value).is_integer():
        return str(int(value))
    return f"{value:.4g}" if abs(value) < 1000 else f"{value:.0f}"


def _csv_number(value) -> str:
    """A counter's total in the CSV: an integer as one, else every digit; ``""`` when none."""
    if value is None:
        return ""
    return str(int(value)) if float(value).is_integer() else repr(float(value))


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
    return {"md": md, "csv": _csv(rows, assessed), "tex": _tex(header, body)}


def _csv(rows: list[dict], assessed: bool) -> str:
    counters = counter_columns(rows)
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
        + [STATS_PREFIX + c for c in counters]
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
            + [_csv_number(r.get("counters", {}).get(c)) for c in counters]  # blank: the guardian reported none
        )
    return buf.getvalue()


def _tex(header: list[str], body: list[list[str]]) -> str:
    cols = "llcr" + "r" * (len(header) - 6)
    tex = f"\\begin{{tabular}}{{{cols}}}\n" + " & ".join(map(tex_cell, header[:-2])) + " \\\\ \\hline\n"
    return (
        tex
        + "".join(
            " & ".join(tex_cell(c).replace("±", "$\\pm$").replace(WILSON_MARK, "$^\\dagger$") for c in b[:-2])
            + " \\\\\n"
            for b in body
        )
        + "\\end{tabular}\n"
    )


def merge_csv(parts: list[tuple[dict, str]], configuration: tuple[str, ...]) -> str:
    """The CSV tables of several configurations in one, each row led by its configuration's columns
    (``configuration``: their names); the columns are every part's, in order of first appearance
    (a counter only one configuration's guardians report is blank in the others' rows)."""
    tables = [(args, list(csv.DictReader(io.StringIO(text)))) for args, text in parts]
    fields = list(configuration)
    for _, text in parts:
        fields += [f for f in next(csv.reader(io.StringIO(text)), []) if f not in fields]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields, restval="", lineterminator="\r\n")
    w.writeheader()
    for args, lines in tables:
        for line in lines:
            w.writerow({c: args.get(c) for c in configuration} | line)
    return buf.getvalue()
