"""The results page: ``rmm-bench report DIR --html`` writes one self-contained HTML file.

Offers :func:`write_page` and :data:`REPLAYS` (the folder of a results directory whose GIFs the
page shows) and :data:`GIF_LIMIT`.

The page holds, per configuration, the Table I table with the stored numbers, the outcome
figure, the paired comparisons of every two agents (:func:`rmm_bench.compare.compare_runs`),
the provenance of every run and merged part, and the GIFs ``rmm-bench replay`` rendered into
``DIR/replays/``.  Everything is inside the file (images as ``data:`` URIs, the style sheet
inline, no script): it opens without network access, reads on a laptop screen (a centred
column, wide tables scroll sideways) and prints (a print style sheet).  Every string that comes
from the database is escaped, so an agent named ``<script>...`` shows as text.
"""

from __future__ import annotations

import base64
import datetime
import html
from pathlib import Path

from rmm_bench.compare_render import p_text
from rmm_bench.names import md_cells
from rmm_bench.outputs import write_output
from rmm_bench.store import ResultsStore

__all__ = ["GIF_LIMIT", "REPLAYS", "write_page"]

#: the folder of a results directory whose ``AGENT-episode-N.gif`` files the page shows
REPLAYS = "replays"
#: GIFs larger than this many bytes are listed but not embedded (the page stays shareable)
GIF_LIMIT = 4_000_000

_CSS = """
body { font: 15px/1.45 system-ui, -apple-system, "Segoe UI", sans-serif; color: #1d1d1f; margin: 0; }
main { max-width: 1100px; margin: 0 auto; padding: 1.5rem 1rem 3rem; }
h1 { font-size: 1.5rem; } h2 { font-size: 1.2rem; margin-top: 2rem; border-bottom: 1px solid #ddd; }
h3 { font-size: 1.05rem; }
.wrap { overflow-x: auto; margin: 0.5rem 0 1rem; }
table { border-collapse: collapse; font-size: 0.85rem; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #ccc; padding: 0.25rem 0.5rem; text-align: right; white-space: nowrap; }
th { background: #f2f2f4; } td:first-child, th:first-child { text-align: left; }
td.text { text-align: left; white-space: normal; }
.note { color: #555; font-size: 0.85rem; } .warn { color: #9a3412; font-weight: 600; }
img { max-width: 100%; height: auto; } figure { margin: 1rem 0; } figcaption { font-size: 0.85rem; color: #555; }
.gifs { display: flex; flex-wrap: wrap; gap: 1rem; } .gifs figure { width: 320px; margin: 0; }
@media print {
  body { font-size: 10pt; color: #000; } main { max-width: none; padding: 0; }
  th { background: none; } .wrap { overflow: visible; }
  tr, figure, img { break-inside: avoid; page-break-inside: avoid; } h2, h3 { break-after: avoid; }
}
"""


def _e(value) -> str:
    return html.escape("" if value is None else str(value), quote=True)


def _md_table(md: str) -> str:
    """The markdown table ``report`` prints, as an HTML table (the same cells, escaped)."""
    lines = [ln for ln in md.splitlines() if ln.startswith("|")]
    if len(lines) < 2:
        return ""
    cells = [md_cells(ln) for ln in lines]  # a name's escaped | stays in its cell
    head, body = cells[0], cells[2:]
    out = ["<div class='wrap'><table class='table-i'><thead><tr>"]
    out += [f"<th>{_e(h)}</th>" for h in head]
    out.append("</tr></thead><tbody>")
    for row in body:
        out.append(f"<tr data-agent='{_e(row[0])}'>" + "".join(f"<td>{_e(c)}</td>" for c in row) + "</tr>")
    out.append("</tbody></table></div>")
    notes = [ln for ln in md.splitlines() if ln and not ln.startswith("|")]
    out += [f"<p class='note'>{_e(n)}</p>" for n in notes]
    return "".join(out)


def _image(path: Path, alt: str) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    kind = "gif" if path.suffix.lower() == ".gif" else "png"
    return f"<img src='data:image/{kind};base64,{data}' alt='{_e(alt)}'>"


def _pct(v) -> str:
    return "—" if v is None or v != v else f"{100 * v:.1f}"


def _comparison(folder: Path, agents: list[str]) -> str:
    if len(agents) < 2:
        return "<p class='note'>No paired comparison: the run holds one agent.</p>"
    from rmm_bench.compare import compare_runs

    try:
        c = compare_runs([folder], agents, resamples=1000)
    except ValueError as e:
        return f"<p class='note'>No paired comparison: {_e(e)}</p>"
    out = [
        "<p class='note'>Every pair of agents over the episodes both ran (same starts): rates in %, the "
        "difference with its 95% paired interval (Newcombe), the discordant episodes (A only, B only) "
        "and the exact McNemar test on them; the episode numbers replay with <code>rmm-bench replay</code>. "
        "Where a guardian raised, the tests run over the episodes where neither errored and the "
        "<em>error</em> row counts the errored ones (no test; the notes below say which).</p>",
        "<div class='wrap'><table class='pairs'><thead><tr>",
        "".join(
            f"<th>{h}</th>"
            for h in (
                "A",
                "B",
                "outcome",
                "episodes",
                "A %",
                "B %",
                "A − B % (95%)",
                "A only",
                "B only",
                "both",
                "McNemar p",
                "A-only episodes",
                "B-only episodes",
            )
        ),  # fmt: skip
        "</tr></thead><tbody>",
    ]
    for r in c.pairs.itertuples():
        diff = "—" if r.diff != r.diff else f"{_pct(r.diff)} [{_pct(r.lo)}, {_pct(r.hi)}]"  # the error row: no test
        out.append(
            f"<tr><td>{_e(r.a)}</td><td>{_e(r.b)}</td><td class='text'>{_e(r.outcome)}</td><td>{r.n}</td>"
            f"<td>{_pct(r.rate_a)}</td><td>{_pct(r.rate_b)}</td>"
            f"<td>{diff}</td><td>{r.a_only}</td><td>{r.b_only}</td>"
            f"<td>{r.both}</td><td>{p_text(r.p_value)}</td><td class='text'>{_e(', '.join(map(str, r.a_only_episodes)))}</td>"
            f"<td class='text'>{_e(', '.join(map(str, r.b_only_episodes)))}</td></tr>"
        )
    out.append("</tbody></table></div>")
    floor = c.floor
    if len(floor):
        doomed = int((floor["doomed"] == True).sum())  # noqa: E712
        out.append(
            f"<p>Floor: {len(floor)} episodes that every agent failed (no goal)"
            + (f", {doomed} of them from doomed starts" if floor["doomed"].notna().all() else "")
            + f"; first: {_e(', '.join(map(str, floor['episode'].head(10))))}.</p>"
        )
    out += [f"<p class='note'>{_e(n)}</p>" for n in c.notes]
    return "".join(out)


def _provenance(store: ResultsStore, run_keys: dict[str, str]) -> str:
    out = [
        "<div class='wrap'><table class='provenance'><thead><tr><th>agent</th><th>run</th><th>version</th>"
        "<th>commit</th><th>python</th><th>platform</th><th>command</th></tr></thead><tbody>"
    ]
    for agent, key in run_keys.items():
        prov = store.run_config(key)["provenance"]
        argv = " ".join(map(str, prov.get("argv") or []))
        out.append(
            f"<tr><td>{_e(agent)}</td><td>{_e(key)}</td><td>{_e(prov.get('package_version'))}</td>"
            f"<td>{_e(prov.get('git_revision'))}</td><td>{_e(prov.get('python'))}</td>"
            f"<td class='text'>{_e(prov.get('platform'))}</td><td class='text'>rmm-bench {_e(argv)}</td></tr>"
        )
    out.append("</tbody></table></div>")
    if store._table_exists("parts"):
        parts = store.db.execute(
            "SELECT source, host, package_version, git_revision, shard, episodes, started, finished FROM parts "
            "ORDER BY part"
        ).fetchall()
        if parts:
            out.append(
                "<h3>Merged parts</h3><div class='wrap'><table class='parts'><thead><tr><th>part</th><th>host</th>"
                "<th>version</th><th>commit</th><th>shard</th><th>episodes</th><th>ran</th></tr></thead><tbody>"
            )
            for src, host, ver, rev, shard, n, started, finished in parts:
                out.append(
                    f"<tr><td class='text'>{_e(src)}</td><td>{_e(host)}</td><td>{_e(ver)}</td><td>{_e(rev)}</td>"
                    f"<td>{_e(shard or 'all')}</td><td>{n}</td><td>{_e(_when(started))} – {_e(_when(finished))}</td></tr>"
                )
            out.append("</tbody></table></div>")
    return "".join(out)


def _when(t) -> str:
    if t is None:
        return "?"
    return datetime.datetime.fromtimestamp(float(t), datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")


def _replays(folder: Path) -> str:
    gifs = sorted((folder / REPLAYS).glob("*.gif")) if (folder / REPLAYS).is_dir() else []
    if not gifs:
        return (
            f"<p class='note'>No rendered replays: <code>rmm-bench replay DIR --agent A --episode N --video "
            f"DIR/{REPLAYS}/A-episode-N.gif</code> puts one here.</p>"
        )
    out = ["<div class='gifs'>"]
    for gif in gifs:
        if gif.stat().st_size > GIF_LIMIT:
            out.append(
                f"<figure><figcaption>{_e(gif.name)}: {gif.stat().st_size / 1e6:.1f} MB, over the page's "
                f"{GIF_LIMIT / 1e6:.0f} MB limit per GIF, not embedded (render it with --every or --size)</figcaption></figure>"
            )
            continue
        out.append(f"<figure>{_image(gif, gif.stem)}<figcaption>{_e(gif.stem)}</figcaption></figure>")
    out.append("</div>")
    return "".join(out)


def write_page(path: Path, folder: Path, store: ResultsStore, sections: list[dict]) -> Path:
    """Write the results page of ``folder`` (its tables already written by ``report``: the
    ``sections`` it filled) to ``path``, atomically; returns ``path``."""
    path = Path(path)
    title = "rmm-bench results"
    body = [f"<h1>{_e(title)}</h1>", f"<p class='note'>Results directory: {_e(folder.name or folder)}</p>"]
    for sec in sections:
        body.append(f"<h2>{_e(sec['title'])}</h2>")
        if sec["notes"].strip():
            body.append(f"<p class='warn'>{_e(sec['notes'].strip())}</p>")
        body.append(_md_table(sec["md"]))
        body.append("<h3>Paired comparisons</h3>")
        body.append(_comparison(folder, list(sec["run_keys"])))
        body.append("<h3>Provenance</h3>")
        body.append(_provenance(store, sec["run_keys"]))
    figure = folder / "outcomes.png"
    if figure.is_file():
        body.append("<h2>Outcomes</h2><figure>" + _image(figure, "outcome rates per agent"))
        body.append("<figcaption>outcomes.png, as rmm-bench report wrote it</figcaption></figure>")
    body.append("<h2>Replays</h2>" + _replays(folder))
    page = (
        "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
        "<meta name='viewport' content='width=device-width, initial-scale=1'>"
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body><main>"
        + "\n".join(body)
        + "</main></body></html>\n"
    )
    return write_output(path, lambda tmp: tmp.write_text(page, encoding="utf-8"))
