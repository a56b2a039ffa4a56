"""``rmm-bench report DIR --html``: one self-contained page with the stored numbers, escaped
strings, the comparisons, the provenance and the rendered replays (the browser test is in
tests/test_html_browser.py, slow tier)."""

from __future__ import annotations

import csv
import json
import re
import shutil
import sqlite3
from html.parser import HTMLParser
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.names import md_cells

EVIL = "<script>alert(1)</script>"


class _Page(HTMLParser):
    """Every tag's attributes, the text of each table row by table class and table by table
    (``tables``: its attributes and rows), and all text."""

    def __init__(self) -> None:
        super().__init__()
        self.attrs: list[tuple[str, dict]] = []
        self.rows: dict[str, list[list[str]]] = {}
        self.tables: list[tuple[dict, list[list[str]]]] = []
        self.text: list[str] = []
        self._table: str | None = None
        self._row: list[str] | None = None
        self._cell: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.attrs.append((tag, a))
        if tag == "table":
            self._table = a.get("class", "")
            self.tables.append((a, []))
        elif tag == "tr":
            self._row = []
        elif tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag):
        if tag in ("td", "th") and self._row is not None and self._cell is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None and self._table is not None:
            self.rows.setdefault(self._table, []).append(self._row)
            self.tables[-1][1].append(self._row)
            self._row = None
        elif tag == "table":
            self._table = None

    def handle_data(self, data):
        self.text.append(data)
        if self._cell is not None:
            self._cell.append(data)


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    return page


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("html") / "run"
    argv = ["--agent", "lrmm,cbf,inactive", "--episodes", "24", "--clock", "fixed:1", "--workers", "1"]
    assert main([*argv, "--no-progress", "--out", str(out)]) == 0
    return out


def _evil_copy(run: Path, tmp_path: Path, name: str = EVIL) -> Path:
    """The run with its inactive agent renamed to a script tag (or ``name``), as a third-party name could be."""
    copy = tmp_path / "evil"
    shutil.copytree(run, copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute("UPDATE runs SET agent = ? WHERE agent = 'inactive'", (name,))
        db.execute("UPDATE episodes SET agent = ? WHERE agent = 'inactive'", (name,))
        for inv, keys in db.execute("SELECT id, run_keys FROM invocations").fetchall():
            keys = {(name if a == "inactive" else a): k for a, k in json.loads(keys).items()}
            db.execute("UPDATE invocations SET run_keys = ? WHERE id = ?", (json.dumps(keys), inv))
    return copy


def page_table_i(page: _Page) -> dict[str, dict[str, str]]:
    """Table I as the page shows it: agent -> header -> cell, the columns equal for every agent
    (which the page moves to the provenance) put back."""
    head, *body = page.rows["table-i"]
    constant = dict(page.rows.get("constant", [])[1:])
    return {
        r[0]: dict(zip(head, r, strict=True)) | {h: v for h, v in constant.items() if h in _MD_HEADERS} for r in body
    }


#: Table I's headers, which the page's provenance shares with other facts (version, commit, ...)
_MD_HEADERS = ("Observation", "Obstacles", "Episodes", "Policy compute time [ms]", "Doomed starts", "Errors")


def stored_table_i(folder: Path) -> dict[str, dict[str, str]]:
    md = [ln for ln in (folder / "table_I.md").read_text().splitlines() if ln.startswith("| ") and "---" not in ln]
    head, *body = map(md_cells, md)  # a name's escaped | stays in its cell
    return {r[0]: dict(zip(head, r, strict=True)) for r in body}


def test_the_page_holds_every_agents_stored_numbers(run, capsys):
    assert main(["report", str(run), "--html"]) == 0
    page_path = run / "results.html"
    assert f"wrote {page_path}" in capsys.readouterr().out
    page = _parse(page_path)
    table = page_table_i(page)
    assert set(table) == {"lrmm", "cbf", "inactive"} and table == stored_table_i(run)  # every cell as printed
    assert "Policy compute time [ms]" not in page.rows["table-i"][0]  # a fixed clock: equal, under Provenance
    pairs = [(a["data-a"], a["data-b"]) for t, a in page.attrs if t == "table" and a.get("class") == "pair"]
    assert pairs == [("cbf", "inactive"), ("cbf", "lrmm"), ("inactive", "lrmm")]  # compare's order
    assert {a["data-outcome"] for t, a in page.attrs if t == "table" and a.get("class") == "matrix"} == {
        "goal",
        "collision",
        "avoidable collision",
        "timeout",
    }
    assert {r[0] for r in page.rows["provenance"][1:]} == {"lrmm", "cbf", "inactive"}


def test_the_page_needs_no_network(run):
    assert main(["report", str(run), "--html", str(run / "page.html")]) == 0
    page = _parse(run / "page.html")
    for tag, attrs in page.attrs:
        for name in ("src", "href"):
            if name in attrs:
                assert attrs[name].startswith(("data:", "#")), (tag, attrs[name])
        assert tag not in ("script", "link", "iframe"), tag
    text = (run / "page.html").read_text()
    assert "@media print" in text and "max-width" in text and "http" not in text.replace("http-equiv", "")


def test_strings_from_the_database_are_escaped(run, tmp_path):
    copy = _evil_copy(run, tmp_path)
    assert main(["report", str(copy), "--html"]) == 0
    raw = (copy / "results.html").read_text()
    assert EVIL not in raw and "&lt;script&gt;alert(1)&lt;/script&gt;" in raw
    page = _parse(copy / "results.html")
    assert EVIL in {r[0] for r in page.rows["table-i"][1:]}  # shown as that text
    assert not any(tag == "script" for tag, _ in page.attrs)


#: a name with every character that shifts a table's columns or breaks its row in some format
PIPES = 'a|b\\|c & 5%_d\nx`y`,"q"'


def test_names_that_split_cells_stay_in_one_cell_in_every_table_format(run, tmp_path):
    copy = _evil_copy(run, tmp_path, PIPES)
    assert main(["report", str(copy), "--html"]) == 0
    lines = [ln for ln in (copy / "table_I.md").read_text().splitlines() if ln.startswith("|")]
    width = len(md_cells(lines[0]))
    assert all(len(md_cells(ln)) == width for ln in lines)  # before: the | added columns, the \n split the row
    assert PIPES in {md_cells(ln)[0] for ln in lines}
    with open(copy / "table_I.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert {len(r) for r in rows} == {len(rows[0])} and PIPES in {r[0] for r in rows}
    tex = [ln for ln in (copy / "table_I.tex").read_text().splitlines() if ln.endswith("\\\\") or "\\hline" in ln]
    assert {len(re.split(r"(?<!\\)&", ln)) for ln in tex} == {width - 2}  # the tex leaves errors and fallbacks out
    assert r"a\textbar{}b\textbackslash{}\textbar{}c \& 5\%\_d x`y`" in (copy / "table_I.tex").read_text()
    page = _parse(copy / "results.html")
    assert len({len(r) for r in page.rows["table-i"]}) == 1 and PIPES in {r[0] for r in page.rows["table-i"]}
    assert page_table_i(page)[PIPES] == stored_table_i(copy)[PIPES]
    pairs = [(a["data-a"], a["data-b"]) for t, a in page.attrs if t == "table" and a.get("class") == "pair"]
    assert PIPES in {a for pair in pairs for a in pair}
    md = compare_runs([copy], ["lrmm", PIPES], resamples=10).to_markdown()
    table = [ln for ln in md.splitlines() if ln.startswith("|")]
    assert [len(md_cells(ln)) for ln in table] == [13] * 6 + [7] * 5  # the outcome rows, the continuous rows
    assert all(md_cells(ln)[1] == PIPES for ln in table[2:6] + table[8:])


def test_rendered_replays_are_embedded(run, tmp_path):
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    gif = copy / "replays" / "lrmm-episode-3.gif"
    gif.parent.mkdir()
    assert main(["replay", str(copy), "--agent", "lrmm", "--episode", "3", "--video", str(gif), "--size", "128"]) == 0
    assert main(["report", str(copy), "--html"]) == 0
    page = _parse(copy / "results.html")
    images = [a["src"] for t, a in page.attrs if t == "img"]
    assert any(s.startswith("data:image/gif;base64,") for s in images)
    assert any(s.startswith("data:image/png;base64,") for s in images)  # the figures
    assert "lrmm-episode-3" in "".join(page.text)


@pytest.mark.parametrize(("make", "expected"), [("empty", "no results.db"), ("newer", "schema version 42")])
def test_bad_input_is_one_line_and_exit_2(run, tmp_path, capsys, make, expected):
    folder = tmp_path / "d"
    if make == "empty":
        folder.mkdir()
    else:
        shutil.copytree(run, folder)
        (folder / "results.html").unlink(missing_ok=True)
        with sqlite3.connect(folder / "results.db") as db:
            db.execute("PRAGMA user_version = 42")
    assert main(["report", str(folder), "--html"]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1
    assert not (folder / "results.html").exists()
