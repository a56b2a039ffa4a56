"""The results page's paired comparisons: one matrix per outcome, each pair's details folded.

Offers :func:`section_comparison` (``compare``'s comparison of one table's agents, in the order
``rmm-bench compare DIR`` puts them) and :func:`pairs_html`.  A matrix's row agent is ``A``, its
column agent ``B`` and a cell ``A - B`` exactly as ``compare`` prints the pair (its upper
triangle: ``compare`` orders the agents by name and pairs each with every later one); the
details of each pair (every outcome's counts, the discordant episodes with the commands that
replay them, the continuous columns, the error row) are inside a ``<details>`` element.  Every
string from the database is escaped.
"""

from __future__ import annotations

import html
import math
import shlex
from pathlib import Path

from rmm_bench.compare import CONTINUOUS, Comparison, compare_runs
from rmm_bench.compare_errors import ERROR
from rmm_bench.compare_render import episodes_cell, p_text, pct
from rmm_bench.pairwise import ALPHA, CORRECTION, OUTCOMES, PairCell, pairwise_matrices
from rmm_bench.side_by_side import REPLAYS, replay_anchor, side_by_side_name

__all__ = ["SHOW", "name_html", "pairs_html", "section_comparison"]

#: discordant episode numbers shown per side of a pair
SHOW = 5


def _e(value) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def name_html(value) -> str:
    """A name (an agent's, a counter's) escaped, breakable after ``_ . : /`` and, when long (over 24
    characters), anywhere; its text unchanged."""
    text = "" if value is None else str(value)
    escaped = "".join(_e(ch) + ("<wbr>" if ch in "_.:/" else "") for ch in text)
    return f"<span class='long'>{escaped}</span>" if len(text) > 24 else escaped


def section_comparison(folder: Path, run_keys: dict[str, str], resamples: int = 1000) -> tuple[Comparison | None, str]:
    """``compare`` of the agents of one table (each by its run: ``NAME@KEY``), in the order
    ``rmm-bench compare`` uses by default (by name), its labels read back as the agents' names;
    or None and why there is none."""
    names = sorted(run_keys)
    if len(names) < 2:
        return None, "the run holds one agent"
    by_key = not any("@" in a for a in names)  # NAME@KEY names one run; a name holding @ cannot
    spec = {f"{a}@{run_keys[a]}" if by_key else a: a for a in names}
    try:
        c = compare_runs([folder], list(spec), resamples=resamples, show=SHOW)
    except ValueError as e:
        return None, str(e)
    if by_key:
        for df in (c.pairs, c.continuous):
            if len(df):
                df["a"], df["b"] = df["a"].map(spec), df["b"].map(spec)
        c.floor = c.floor.rename(columns={f"outcome:{s}": f"outcome:{a}" for s, a in spec.items()})
        notes = []
        for note in c.notes:
            for s, a in spec.items():
                note = note.replace(s, a)
            notes.append(note)
        c.notes, c.agents = notes, [spec[s] for s in c.agents]
    return c, ""


def _signed(v: float) -> str:
    return "—" if v is None or math.isnan(v) else f"{100 * v:+.1f}"


def _cell(cell: PairCell | None) -> str:
    if cell is None:
        return "<td class='none'></td>"
    if not cell.tested:
        return "<td class='none' data-tested='no'>no test</td>"
    better = cell.better()
    css = "" if better is None else " better" if better == cell.a else " worse"
    mark = "*" if cell.significant else ""
    title = (
        f"{cell.a} − {cell.b}, {cell.outcome}: {_signed(cell.diff)} points [{_signed(cell.lo)}, {_signed(cell.hi)}], "
        f"McNemar p {p_text(cell.p_value)}, {CORRECTION} p {p_text(cell.p_holm)}"
    )
    return (
        f"<td class='cell{css}' title='{_e(title)}' data-diff='{100 * cell.diff:.1f}' data-p='{cell.p_value:.6g}' "
        f"data-p-holm='{cell.p_holm:.6g}' data-significant='{'yes' if cell.significant else 'no'}'>"
        f"<span class='d'>{_signed(cell.diff)}{mark}</span> "
        f"<span class='ci'>[{_signed(cell.lo)}, {_signed(cell.hi)}]</span></td>"
    )


def _matrix(outcome: str, matrix: dict[tuple[str, str], PairCell], names: list[str], compared: set) -> str:
    label, lower = OUTCOMES[outcome]
    m = sum(c.tested for c in matrix.values())
    out = [
        f"<h4>{_e(label)} rate: row − column, percentage points</h4>",
        f"<div class='wrap'><table class='matrix' data-outcome='{_e(outcome)}' data-pairs='{m}'><thead><tr>"
        "<th class='corner'>A \\ B</th>",
    ]
    out += [f"<th scope='col'>{name_html(b)}</th>" for b in names[1:]]
    out.append("</tr></thead><tbody>")
    for i, a in enumerate(names[:-1]):
        out.append(f"<tr><th scope='row'>{name_html(a)}</th>")
        for j, b in enumerate(names[1:], 1):
            if j <= i:
                out.append("<td class='none'></td>")
            elif (a, b) in matrix:
                out.append(_cell(matrix[(a, b)]))
            else:  # compared, but an agent errored in every episode: the pair's error row only
                out.append("<td class='none' data-tested='no'>no test</td>" if (a, b) in compared else _cell(None))
        out.append("</tr>")
    out.append("</tbody></table></div>")
    out.append(
        f"<p class='note'>{m} pairs; green: the row agent {'lower' if lower else 'higher'} (better), red: the "
        f"column agent better, both only where significant (*).</p>"
    )
    return "".join(out)


def _replays(folder: Path, a: str, b: str, rows) -> str:
    """The command that replays the first discordant episode of each side of each outcome, both
    agents side by side into ``DIR/replays/`` (where the page shows it), and a link to that replay
    when it is there."""
    episodes = list(dict.fromkeys(e for r in rows for eps in (r.a_only_episodes, r.b_only_episodes) for e in eps[:1]))
    if not episodes:
        return ""
    where = shlex.quote(str(folder))
    items = []
    for e in episodes:
        name = side_by_side_name((a, b), e)
        video = shlex.quote(str(folder / REPLAYS / name))
        item = (
            f"<code>rmm-bench replay {_e(where)} --agent {_e(shlex.quote(f'{a},{b}'))} --episode {e} --size 320 "
            f"--video {_e(video)}</code>"
        )
        if (folder / REPLAYS / name).is_file():
            item += f" (<a href='#{_e(replay_anchor(name))}'>watch episode {e}</a>)"
        items.append(f"<li>{item}</li>")
    return (
        "<p class='note'>Replay a discordant episode (the first of each side), both agents side by side, into "
        f"the Replays section below:</p><ul class='replay'>{''.join(items)}</ul>"
    )


def _continuous(cont) -> str:
    if not len(cont):
        return ""

    def num(v: float) -> str:
        return "—" if math.isnan(v) else f"{v:.3g}"

    out = [
        "<div class='wrap'><table class='continuous'><thead><tr><th>column</th><th>episodes</th><th>A</th>"
        "<th>B</th><th>A − B (95%, paired bootstrap)</th></tr></thead><tbody>"
    ]
    for r in cont.itertuples():
        what, unit = CONTINUOUS[r.column]
        out.append(
            f"<tr><td class='text' title='{_e(what)}'>{_e(r.column.replace('_', ' '))} [{_e(unit)}]</td><td>{r.n}</td>"
            f"<td>{num(r.mean_a)}</td><td>{num(r.mean_b)}</td>"
            f"<td>{num(r.diff)} [{num(r.lo)}, {num(r.hi)}]</td></tr>"
        )
    out.append("</tbody></table></div>")
    return "".join(out)


def _pair(folder: Path, a: str, b: str, c: Comparison, matrices: dict) -> str:
    rows = [r for r in c.pairs.itertuples() if r.a == a and r.b == b]
    said = []
    for outcome, matrix in matrices.items():
        cell = matrix.get((a, b))
        if cell is not None and cell.tested:
            said.append(
                f"{'success' if outcome == 'goal' else outcome} {_signed(cell.diff)}{'*' if cell.significant else ''}"
            )
    if any(r.outcome == ERROR for r in rows):
        said.append("errors")
    out = [
        f"<details class='pair'><summary><strong>{_e(a)} − {_e(b)}</strong>: {_e(', '.join(said))}</summary>",
        f"<p class='note'>A = {_e(a)}, B = {_e(b)}; rates in %, the difference in points with its 95% paired "
        f"interval (Newcombe), McNemar's exact p and {CORRECTION}'s.</p>",
        f"<div class='wrap'><table class='pair' data-a='{_e(a)}' data-b='{_e(b)}'><thead><tr><th>outcome</th>"
        "<th>episodes</th><th>A %</th><th>B %</th><th>A − B (95%)</th><th>p (Holm)</th>"
        "<th>only A: episodes</th><th>only B: episodes</th></tr></thead><tbody>",
    ]
    for r in rows:
        cell = matrices.get(r.outcome, {}).get((a, b))
        holm = f" ({p_text(cell.p_holm)})" if cell is not None and cell.tested else ""
        diff = (
            "—" if math.isnan(r.diff) and math.isnan(r.lo) else f"{_signed(r.diff)} [{_signed(r.lo)}, {_signed(r.hi)}]"
        )
        only_a = f"{r.a_only}: {episodes_cell(r.a_only_episodes, r.a_only, SHOW)}" if r.a_only else "0"
        only_b = f"{r.b_only}: {episodes_cell(r.b_only_episodes, r.b_only, SHOW)}" if r.b_only else "0"
        out.append(
            f"<tr><td class='text'>{_e(r.outcome)}</td><td>{r.n}</td><td>{pct(r.rate_a)}</td><td>{pct(r.rate_b)}</td>"
            f"<td>{diff}</td><td>{p_text(r.p_value)}{holm}</td><td class='text'>{_e(only_a)}</td>"
            f"<td class='text'>{_e(only_b)}</td></tr>"
        )
    out.append("</tbody></table></div>")
    out.append(_replays(folder, a, b, rows))
    if len(c.continuous):
        out.append(_continuous(c.continuous[(c.continuous["a"] == a) & (c.continuous["b"] == b)]))
    notes = dict.fromkeys(r.note for r in rows if r.note)
    out += [f"<p class='note'>{_e(n)}</p>" for n in notes]
    out.append("</details>")
    return "".join(out)


def _floor(c: Comparison) -> str:
    floor = c.floor
    if not len(floor):
        return ""
    doomed = int((floor["doomed"] == True).sum())  # noqa: E712
    return (
        f"<p>Floor: {len(floor)} episodes that every agent failed (no goal)"
        + (f", {doomed} of them from doomed starts" if floor["doomed"].notna().all() else "")
        + f"; first: {_e(', '.join(map(str, floor['episode'].head(10))))}.</p>"
    )


def pairs_html(folder: Path, c: Comparison | None, why: str, matrices: dict | None = None) -> str:
    """The section's paired comparisons: the matrices, the floor, the notes and each pair folded."""
    if c is None:
        return f"<p class='note'>No paired comparison: {_e(why)}</p>"
    matrices = pairwise_matrices(c.pairs) if matrices is None else matrices
    names = list(c.agents)
    out = [
        "<p class='note'>Every pair of agents over the episodes both ran (same starts), ordered as "
        "<code>rmm-bench compare DIR</code> orders them (by name; each cell is row − column, as it prints the "
        "pair). A cell is the difference of the two rates in percentage points and its 95% paired interval "
        f"(Newcombe); * marks a difference significant after {CORRECTION} over that outcome's pairs: the "
        f"exact McNemar test on the discordant episodes, family-wise error rate {ALPHA:.0%}. Where a guardian "
        "raised, the tests run over the episodes where neither errored (the notes say which).</p>"
    ]
    pairs = list(dict.fromkeys((r.a, r.b) for r in c.pairs.itertuples()))
    out += [_matrix(outcome, matrix, names, set(pairs)) for outcome, matrix in matrices.items()]
    out.append(_floor(c))
    out += [f"<p class='note'>{_e(n)}</p>" for n in c.notes]
    out.append(f"<h4>Each pair ({len(pairs)}): counts, discordant episodes, continuous columns</h4>")
    out += [_pair(folder, a, b, c, matrices) for a, b in pairs]
    return "".join(out)
