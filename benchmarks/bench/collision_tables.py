"""How ``rmm-bench collisions`` shows its verdicts: the totals per class, and the markdown, csv and
json tables (:mod:`rmm_bench.collisions`)."""

from __future__ import annotations

import csv
import io
import json
import math
import statistics
from dataclasses import asdict

from rmm_bench.collision_classes import CLASSES, UNVERIFIED, Selection, Verdict

__all__ = ["to_csv", "to_json", "to_markdown", "totals"]


def _s(x: float, digits: int = 2) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.{digits}f}"


def totals(verdicts: list[Verdict]) -> list[dict]:
    """Per class (those with an episode, in :data:`CLASSES` order, then ``not verified``): the
    count, its share and the median time from first crossing to impact."""
    n = len(verdicts)
    rows = []
    for cls in (*CLASSES, UNVERIFIED):
        of = [v for v in verdicts if v.cls == cls]
        if not of:
            continue
        times = [v.alarm_to_impact_s for v in of if not math.isnan(v.alarm_to_impact_s)]
        rows.append(
            {
                "class": cls,
                "episodes": len(of),
                "share": len(of) / n,
                "median_alarm_to_impact_s": statistics.median(times) if times else math.nan,
                "with_alarm": len(times),
            }
        )
    return rows


def _yes(b: bool | None) -> str:
    return "?" if b is None else ("yes" if b else "no")


def _rule(last_steps: int, window: float | None) -> str:
    w = "over the whole episode" if window is None else f"up within {window:g} s before impact"
    return f"the first alarm {w} (traced back to where it began), in time if before the last {last_steps} steps"


def to_markdown(sel: Selection, verdicts: list[Verdict], last_steps: int, window: float | None) -> str:
    signal = any(v.signal for v in verdicts)
    what = f"{sel.agent}'s collisions" + (f" that {sel.versus} avoids" if sel.versus else "")
    alarm = (
        f"{sel.agent}'s alarm() (value > threshold)"
        if signal
        else f"none: {sel.agent} has no alarm(), its first step in control stands for it"
    )
    lines = [
        f"## {what}: {sel.describe}",
        "",
        f"{len(verdicts)} episodes (of its {sel.collisions} collisions; run {sel.run_key}"
        + (f", {sel.versus}'s run {sel.versus_key}" if sel.versus else "")
        + f"). Alarm: {alarm}; the crossing: {_rule(last_steps, window)}.",
        "",
        "| class | episodes | share | median first alarm to impact (s) |",
        "|---|---:|---:|---:|",
    ]
    for t in totals(verdicts):
        lines.append(
            f"| {t['class']} | {t['episodes']} | {100 * t['share']:.0f}% | {_s(t['median_alarm_to_impact_s'])}"
            + (f" ({t['with_alarm']} with an alarm)" if t["with_alarm"] != t["episodes"] else "")
            + " |"
        )
    all_t = [v.alarm_to_impact_s for v in verdicts if not math.isnan(v.alarm_to_impact_s)]
    lines.append(f"| total | {len(verdicts)} | 100% | {_s(statistics.median(all_t)) if all_t else '-'} |")
    head = (
        "| episode | seed | class | doomed | steps | impact (s) | first alarm (s) | alarm to impact (s) "
        "| in control at impact | peak before | threshold |"
    )
    rule = "|---:|---:|---|---|---:|---:|---:|---:|---|---:|---:|"
    if sel.versus:
        head += f" {sel.versus} outcome | {sel.versus} in control before impact (s) |"
        rule += "---|---:|"
    lines += ["", head, rule]
    for v in verdicts:
        line = (
            f"| {v.episode} | {v.seed} | {v.cls} | {_yes(v.doomed)} | {v.steps} | {_s(v.impact_s)} | "
            f"{_s(v.first_alarm_s)} | {_s(v.alarm_to_impact_s)} | {_yes(v.in_control_at_impact)} | "
            f"{_s(v.peak_before, 3)} | {_s(v.threshold, 3)} |"
        )
        if sel.versus:
            line += f" {v.versus_outcome or '-'} | {_s(v.versus_control_lead_s)} |"
        lines.append(line)
    notes = [f"episode {v.episode}: {v.note}" for v in verdicts if v.note]
    if notes:
        lines += [""] + [f"Note: {n}" for n in notes]
    return "\n".join(lines) + "\n"


def _plain(x):
    return None if isinstance(x, float) and math.isnan(x) else x


def to_csv(verdicts: list[Verdict]) -> str:

    buf = io.StringIO()
    fields = list(asdict(verdicts[0]))
    w = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
    w.writeheader()
    for v in verdicts:
        w.writerow({k: ("" if _plain(x) is None else x) for k, x in asdict(v).items()})
    return buf.getvalue()


def to_json(sel: Selection, verdicts: list[Verdict], last_steps: int, window: float | None) -> str:
    doc = {
        "agent": sel.agent,
        "run_key": sel.run_key,
        "world": sel.describe,
        "versus": sel.versus,
        "versus_run_key": sel.versus_key,
        "last_steps": last_steps,
        "window_s": window,
        "collisions": sel.collisions,
        "totals": [{k: _plain(x) for k, x in t.items()} for t in totals(verdicts)],
        "episodes": [{k: _plain(x) for k, x in asdict(v).items()} for v in verdicts],
    }
    return json.dumps(doc, indent=1) + "\n"


# ---------------------------------------------------------------- the command
