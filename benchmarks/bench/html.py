"""The results page: ``rmm-bench report DIR --html`` writes one self-contained HTML file.

Offers :func:`write_page`, :data:`REPLAYS` (the folder of a results directory whose GIFs the
page shows; :mod:`rmm_bench.side_by_side` names it), :data:`GIF_LIMIT` and :data:`PAGE_LIMIT`.

The page leads with the answer.  Per configuration (one table of ``report``): a figure of every
agent's success, collision, avoidable-collision and timeout rates with their 95% intervals
(:func:`rmm_bench.report_figures.plot_rates`; side by side on a wide screen, stacked on a
narrow one), a paragraph generated from the numbers (:func:`rmm_bench.pairwise.summary`), then
Table I with the stored numbers (the columns equal for every agent moved to the provenance),
each guardian's own counters (its ``stats()``, summed over the episodes), one matrix of paired
differences per outcome with each pair's details folded (:mod:`rmm_bench.html_pairs`), and the
provenance of every run and merged part.  After them, ``outcomes.png`` and the GIFs
``rmm-bench replay`` rendered into ``DIR/replays/``, as many as keep the page under
:data:`PAGE_LIMIT` (the others are listed).  Everything is inside the file (images as ``data:``
URIs, the style sheet inline, no script): it opens without network access, fits a laptop's
width without sideways scrolling and reads on a phone, and prints (a print style sheet).  Every
string that comes from the database is escaped, so an agent named ``<script>...`` shows as text.
"""

from __future__ import annotations

import base64
import datetime
import html
from pathlib import Path

from rmm_bench.html_pairs import name_html as _name
from rmm_bench.html_pairs import pairs_html, section_comparison
from rmm_bench.names import md_cells
from rmm_bench.outputs import write_output
from rmm_bench.pairwise import pairwise_matrices, summary
from rmm_bench.report_figures import plot_rates
from rmm_bench.report_tables import counter_columns, counter_text
from rmm_bench.runner import is_timing_stat
from rmm_bench.side_by_side import REPLAYS, replay_anchor
from rmm_bench.store import ResultsStore

__all__ = ["GIF_LIMIT", "PAGE_LIMIT", "REPLAYS", "write_page"]

#: GIFs larger than this many bytes are listed but not embedded (the page stays shareable)
GIF_LIMIT = 4_000_000
#: the page's size budget in bytes: GIFs that would take it over are listed, not embedded
PAGE_LIMIT = 20_000_000
#: the width below which the figure's panels are stacked (CSS pixels)
NARROW = 900

_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d1d1f; margin: 0; }
main { max-width: 1100px; margin: 0 auto; padding: 1.5rem 1rem 3rem; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; margin-top: 2rem; border-bottom: 1px solid #ddd; }
h3 { font-size: 1.05rem; margin-top: 1.75rem; } h4 { font-size: 0.95rem; margin: 1.25rem 0 0.25rem; }
.wrap { max-width: 100%; overflow-x: auto; margin: 0.5rem 0 1rem; }
table { border-collapse: collapse; font-size: 0.85rem; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.45rem; text-align: right; vertical-align: top; }
th { background: #f2f2f4; font-weight: 600; overflow-wrap: break-word; }
td:first-child, th:first-child, th[scope=row] { text-align: left; overflow-wrap: break-word; }
td.text { text-align: left; overflow-wrap: anywhere; } .nw { white-space: nowrap; } .long { overflow-wrap: anywhere; }
table.matrix td { font-size: 0.8rem; } table.matrix .ci { display: block; color: #555; font-size: 0.72rem; }
table.matrix td.better { background: #dcf3e3; } table.matrix td.worse { background: #fbe0e0; }
table.matrix td.none { background: #fafafa; color: #888; }
.note { color: #555; font-size: 0.85rem; } .warn { color: #9a3412; font-weight: 600; }
.summary { font-size: 1rem; background: #f6f8fa; border-left: 4px solid #4b7bd1; padding: 0.6rem 0.9rem; }
img { max-width: 100%; height: auto; } figure { margin: 1rem 0; } figcaption { font-size: 0.85rem; color: #555; }
details.pair { border: 1px solid #ddd; border-radius: 4px; padding: 0.3rem 0.6rem; margin: 0.3rem 0; }
details.pair summary { cursor: pointer; } ul.replay { font-size: 0.8rem; padding-left: 1.2rem; }
code { overflow-wrap: anywhere; }
.gifs { display: flex; flex-wrap: wrap; gap: 1rem; } .gifs figure { width: 320px; max-width: 100%; margin: 0; }
@media (max-width: 800px) { main { padding: 1rem 0.5rem 2rem; } table { font-size: 0.78rem; }
  th, td { padding: 0.2rem 0.3rem; } }
@media print {
  body { font-size: 10pt; color: #000; } main { max-width: none; padding: 0; }
  th { background: none; } .wrap { overflow: visible; }
  tr, figure, img { break-inside: avoid; page-break-inside: avoid; } h2, h3 { break-after: avoid; }
}
"""


def _e(value) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def _data(data: bytes, image_format: str) -> str:
    return f"data:image/{image_format};base64,{base64.b64encode(data).decode()}"


def _value(text: str) -> str:
    """A cell's text escaped, a rate's spread kept with it (``74.7 ± 4.3`` breaks before the ±)."""
    mean, pm, spread = text.partition(" ± ")
    return f"<span class='nw'>{_e(mean)}</span> <span class='nw'>± {_e(spread)}</span>" if pm else _e(text)


def _table_i(md: str) -> tuple[str, list[tuple[str, str]]]:
    """The markdown table ``report`` prints as an HTML table (the same cells, escaped) and the
    columns equal in every row (with two rows or more), which the table leaves out: ``(header, value)``."""
    lines = [ln for ln in md.splitlines() if ln.startswith("|")]
    if len(lines) < 2:
        return "", []
    cells = [md_cells(ln) for ln in lines]  # a name's escaped | stays in its cell
    head, body = cells[0], cells[2:]
    constant = [j for j in range(1, len(head)) if len(body) > 1 and len({row[j] for row in body}) == 1]
    keep = [j for j in range(len(head)) if j not in constant]
    out = ["<div class='wrap'><table class='table-i'><thead><tr>"]
    out += [f"<th>{_e(head[j])}</th>" for j in keep]
    out.append("</tr></thead><tbody>")
    for row in body:
        shown = [_name(row[0])] + [_value(row[j]) for j in keep[1:]]
        out.append(f"<tr data-agent='{_e(row[0])}'>" + "".join(f"<td>{c}</td>" for c in shown) + "</tr>")
    out.append("</tbody></table></div>")
    notes = [ln for ln in md.splitlines() if ln and not ln.startswith("|")]
    if constant:
        notes.append("Equal for every agent, so under Provenance: " + ", ".join(head[j] for j in constant) + ".")
    out += [f"<p class='note'>{_e(n)}</p>" for n in notes]
    return "".join(out), [(head[j], body[0][j]) for j in constant]


def _counters(rows: list[dict]) -> str:
    """Each guardian's own statistics (its ``stats()``), summed over its episodes, one column each."""
    names = counter_columns(rows)
    if not names:
        return "<p class='note'>No guardian reported statistics of its own (<code>stats()</code>).</p>"
    timing = [n for n in names if is_timing_stat(n)]
    out = ["<div class='wrap'><table class='counters'><thead><tr><th>Agent</th>"]
    out += [f"<th>{_name(n)}{' †' if n in timing else ''}</th>" for n in names]
    out.append("</tr></thead><tbody>")
    for r in rows:
        counts = r.get("counters", {})
        out.append(
            f"<tr data-agent='{_e(r['agent'])}'><td>{_name(r['agent'])}</td>"
            + "".join(f"<td>{_e(counter_text(counts.get(n)) or '—')}</td>" for n in names)
            + "</tr>"
        )
    out.append("</tbody></table></div>")
    note = "Each guardian's own <code>stats()</code>, summed over its episodes; —: it reports no such statistic"
    if timing:
        note += "; †: a time or this machine's cache state, not a result (a replay does not compare it)"
    return "".join(out) + f"<p class='note'>{note}. Table I's CSV holds them as <code>stats.NAME</code> columns.</p>"


def _figure(rows: list[dict]) -> str:
    """The rates figure: four panels side by side, stacked below :data:`NARROW` pixels."""
    if not rows:
        return ""
    wide = plot_rates(rows, layout="row")
    narrow = plot_rates(rows, layout="column")
    return (
        "<figure class='rates'><picture>"
        f"<source media='(max-width: {NARROW}px)' srcset='{_data(narrow, 'png')}'>"
        f"<img src='{_data(wide, 'png')}' alt='success, collision, avoidable-collision and timeout rate of every "
        "agent with its 95% interval'></picture><figcaption>Each agent's rates in % of its episodes with a result "
        "(avoidable collisions: of its avoidable starts), with 95% Wilson score intervals over those episodes; "
        "fewest collisions first. Table I's ± is the spread over batches, the paper's.</figcaption></figure>"
    )


def _provenance(store: ResultsStore, run_keys: dict[str, str], constant: list[tuple[str, str]]) -> str:
    fields = [
        ("version", "package_version"),
        ("commit", "git_revision"),
        ("python", "python"),
        ("platform", "platform"),
    ]
    provs = {agent: store.run_config(key)["provenance"] for agent, key in run_keys.items()}
    same = [(label, k) for label, k in fields if len(provs) > 1 and len({str(p.get(k)) for p in provs.values()}) == 1]
    varying = [(label, k) for label, k in fields if (label, k) not in same]
    out = []
    shared = [(h, v) for h, v in constant] + [(label, next(iter(provs.values())).get(k)) for label, k in same]
    if shared:
        out.append("<div class='wrap'><table class='constant'><thead><tr><th>equal for every agent</th><th>value</th>")
        out.append("</tr></thead><tbody>")
        out += [f"<tr><td>{_e(h)}</td><td class='text'>{_e(v)}</td></tr>" for h, v in shared]
        out.append("</tbody></table></div>")
    out.append("<div class='wrap'><table class='provenance'><thead><tr><th>agent</th><th>run</th>")
    out += [f"<th>{label}</th>" for label, _ in varying]
    out.append("<th>command</th></tr></thead><tbody>")
    for agent, key in run_keys.items():
        prov = provs[agent]
        argv = " ".join(map(str, prov.get("argv") or []))
        out.append(
            f"<tr><td>{_e(agent)}</td><td>{_e(key)}</td>"
            + "".join(f"<td class='text'>{_e(prov.get(k))}</td>" for _, k in varying)
            + f"<td class='text'>rmm-bench {_e(argv)}</td></tr>"
        )
    out.append("</tbody></table></div>")
    if store._table_exists("parts"):
        parts = store.db.execute(
            "SELECT source, host, package_version, git_revision, shard, episodes, started, finished FROM parts "
            "ORDER BY part"
        ).fetchall()
        if parts:
            out.append(
                "<h4>Merged parts</h4><div class='wrap'><table class='parts'><thead><tr><th>part</th><th>host</th>"
                "<th>version</th><th>commit</th><th>shard</th><th>episodes</th><th>ran</th></tr></thead><tbody>"
            )
            for src, host, ver, rev, shard, n, started, finished in parts:
                out.append(
                    f"<tr><td class='text'>{_e(src)}</td><td>{_e(host)}</td><td>{_e(ver)}</td><td class='text'>"
                    f"{_e(rev)}</td><td>{_e(shard or 'all')}</td><td>{n}</td><td class='text'>{_e(_when(started))} – "
                    f"{_e(_when(finished))}</td></tr>"
                )
            out.append("</tbody></table></div>")
    return "".join(out)


def _when(t) -> str:
    if t is None:
        return "?"
    return datetime.datetime.fromtimestamp(float(t), datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def _replays(folder: Path, budget: int) -> str:
    """The rendered GIFs, embedded while the page stays within ``budget`` more bytes; the rest listed."""
    gifs = sorted((folder / REPLAYS).glob("*.gif")) if (folder / REPLAYS).is_dir() else []
    if not gifs:
        return (
            f"<p class='note'>No rendered replays: <code>rmm-bench replay DIR --agent A --episode N --video "
            f"DIR/{REPLAYS}/A-episode-N.gif</code> puts one here, <code>--agent A,B --video "
            f"DIR/{REPLAYS}/A-vs-B-episode-N.gif</code> two agents side by side.</p>"
        )
    out, skipped = ["<div class='gifs'>"], []
    for gif in gifs:
        size = gif.stat().st_size
        if size > GIF_LIMIT:
            skipped.append(f"{gif.name} ({size / 1e6:.1f} MB, over the {GIF_LIMIT / 1e6:.0f} MB limit per GIF)")
            continue
        encoded = 4 * ((size + 2) // 3) + 200
        if encoded > budget:
            skipped.append(f"{gif.name} ({size / 1e6:.1f} MB, over the page's {PAGE_LIMIT / 1e6:.3g} MB budget)")
            continue
        budget -= encoded
        out.append(
            f"<figure id='{_e(replay_anchor(gif.name))}'><img src='{_data(gif.read_bytes(), 'gif')}' "
            f"alt='{_e(gif.stem)}'>"
            f"<figcaption>{_e(gif.stem)}</figcaption></figure>"
        )
    out.append("</div>")
    if skipped:
        out.append(
            "<p class='note'>Not embedded (render them smaller with --every or --size): "
            + _e("; ".join(skipped))
            + ".</p>"
        )
    return "".join(out)


def _robustness(folder: Path) -> list[str]:
    """The disturbance sweep ``rmm-bench sweep --disturb`` wrote in ``folder`` (its figure and
    table, escaped), or nothing when there is none."""
    md_path = folder / "disturbance_sweep.md"
    if not md_path.is_file():
        return []
    text = md_path.read_text(encoding="utf-8")
    intro = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("|")]
    rows = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in text.splitlines() if ln.startswith("|")]
    out = ["<h2>Robustness: who degrades least</h2>"] + [f"<p class='note'>{_e(ln)}</p>" for ln in intro]
    png = folder / "disturbance_sweep.png"
    if png.is_file():
        out.append(
            f"<figure><img src='{_data(png.read_bytes(), 'png')}' alt='collision rate against the disturbance level, "
            "one curve per agent'><figcaption>disturbance_sweep.png</figcaption></figure>"
        )
    if len(rows) >= 2:
        head = "".join(f"<th>{_e(c)}</th>" for c in rows[0])
        body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in r) + "</tr>" for r in rows[2:])
        out.append(f"<div class='tw'><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>")
    return out


def _section(folder: Path, store: ResultsStore, sec: dict) -> list[str]:
    c, why = section_comparison(folder, sec["run_keys"])
    matrices = pairwise_matrices(c.pairs) if c is not None else None
    table, constant = _table_i(sec["md"])
    body = [f"<h2>{_e(sec['title'].replace('Table I', 'Results', 1))}</h2>"]
    if sec["notes"].strip():
        body.append(f"<p class='warn'>{_e(sec['notes'].strip())}</p>")
    body.append(_figure(sec["rows"]))
    body.append(f"<p class='summary'>{_e(summary(sec['rows'], matrices))}</p>")
    body += ["<h3>Table I</h3>", table, "<h3>Guardian counters</h3>", _counters(sec["rows"])]
    body += ["<h3>Paired comparisons</h3>", pairs_html(folder, c, why, matrices)]
    body += ["<h3>Provenance</h3>", _provenance(store, sec["run_keys"], constant)]
    return body


def write_page(path: Path, folder: Path, store: ResultsStore, sections: list[dict]) -> Path:
    """Write the results page of ``folder`` (its tables already written by ``report``: the
    ``sections`` it filled) to ``path``, atomically; returns ``path``."""
    path = Path(path)
    title = "rmm-bench results"
    body = [f"<h1>{_e(title)}</h1>", f"<p class='note'>Results directory: {_e(folder.name or folder)}</p>"]
    for sec in sections:
        body += _section(folder, store, sec)
    figure = folder / "outcomes.png"
    if figure.is_file():
        body.append(
            f"<h2>Outcomes and compute time</h2><figure><img src='{_data(figure.read_bytes(), 'png')}' "
            "alt='outcome rates per agent, and collisions against compute time'>"
            "<figcaption>outcomes.png, as rmm-bench report wrote it</figcaption></figure>"
        )
    body += _robustness(folder)
    head = (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body><main>"
    )
    size = len(head.encode()) + sum(len(b.encode()) for b in body) + 100
    body.append("<h2>Replays</h2>" + _replays(folder, PAGE_LIMIT - size))
    page = head + "\n".join(body) + "</main></body></html>\n"
    return write_output(path, lambda tmp: tmp.write_text(page, encoding="utf-8"))
