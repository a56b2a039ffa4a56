"""The results page leads with the answer (issue 53): the summary names the least-colliding agent,
one matrix per outcome holds each pair's difference and its significance after Holm-Bonferroni
(checked by hand on known outcomes), ordered and signed as ``rmm-bench compare`` prints the
pairs; columns equal for every agent move to the provenance; a third-party guardian's counter
is a column of the page and of Table I's CSV; ``report DIR`` shows every agent of the newest
configuration; replays beyond the page's budget are listed, not embedded."""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
import sqlite3
from pathlib import Path

import pytest

import rmm_bench.html
from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.paired import mcnemar_exact
from rmm_bench.pairwise import holm
from tests.test_html import _parse

ROOT = Path(__file__).resolve().parents[1]

FIXED = ["--clock", "fixed:1", "--workers", "1", "--no-progress"]
EPISODES = 12
#: the episodes each agent collides in; every other episode ends at the goal (brakes: timeout)
COLLIDES = {"brakes": range(1), "inactive": range(7), "random": range(10)}


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    """A run of brakes, inactive and random whose outcomes are set to :data:`COLLIDES`, with its page."""
    out = tmp_path_factory.mktemp("known") / "run"
    assert main(["--agent", "random,inactive,brakes", "--episodes", str(EPISODES), *FIXED, "--out", str(out)]) == 0
    with sqlite3.connect(out / "results.db") as db:
        for agent, eps in COLLIDES.items():
            rest = "timeout" if agent == "brakes" else "goal"
            db.execute("UPDATE episodes SET outcome = ? WHERE agent = ?", (rest, agent))
            db.execute(
                f"UPDATE episodes SET outcome = 'collision' WHERE agent = ? AND episode IN ({','.join('?' * len(eps))})",
                (agent, *eps),
            )
    assert main(["report", str(out), "--html"]) == 0
    return out


def _cells(page, outcome: str) -> dict[tuple[str, str], dict]:
    """The matrix of ``outcome``: (row agent, column agent) -> the cell's attributes (+ its text)."""
    html = (page).read_text(encoding="utf-8")
    table = re.search(rf"<table class='matrix' data-outcome='{outcome}'.*?</table>", html, re.S).group(0)
    cols = [re.sub("<[^>]+>", "", c) for c in re.findall(r"<th scope='col'>(.*?)</th>", table)]
    out = {}
    for row in re.findall(r"<tr><th scope='row'>(.*?)</th>(.*?)</tr>", table, re.S):
        a = re.sub("<[^>]+>", "", row[0])
        for b, td in zip(cols, re.findall(r"<td[^>]*>.*?</td>|<td[^>]*></td>", row[1], re.S), strict=True):
            attrs = dict(re.findall(r"data-([\w-]+)='([^']*)'", td))
            if attrs:
                out[(a, b)] = attrs | {"text": re.sub("<[^>]+>", "", td)}
    return out


def test_holm_adjusts_by_hand():
    adjusted = holm([0.01, 0.04, 0.03, math.nan, 0.005])
    # sorted: 0.005 x 4 = 0.02; 0.01 x 3 = 0.03; 0.03 x 2 = 0.06; 0.04 x 1 = 0.04 -> kept at 0.06
    assert adjusted[:3] == pytest.approx([0.03, 0.06, 0.06]) and math.isnan(adjusted[3])
    assert adjusted[4] == pytest.approx(0.02)
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])  # capped at 1


def test_the_summary_names_the_least_colliding_agent(known):
    page = _parse(known / "results.html")
    text = " ".join("".join(page.text).split())
    assert "brakes collides least: 8.3% of 12 episodes" in text
    # paired: 9 episodes only random collided in (p 2/512, Holm x3), 6 only inactive (p 2/64, Holm x2 = 0.0625)
    assert "it collides significantly less than random and no differently from inactive" in text


def test_the_matrix_entries_and_the_correction_by_hand(known):
    cells = _cells(known / "results.html", "collision")
    assert set(cells) == {("brakes", "inactive"), ("brakes", "random"), ("inactive", "random")}
    p = {pair: mcnemar_exact(0, COLLIDES[pair[1]].stop - COLLIDES[pair[0]].stop) for pair in cells}
    assert p == {("brakes", "inactive"): 2 / 2**6, ("brakes", "random"): 2 / 2**9, ("inactive", "random"): 2 / 2**3}
    by_hand = {  # Holm over the 3 pairs: 3 x 2/512, then max(., 2 x 2/64), then max(., 1 x 2/8)
        ("brakes", "random"): 3 * 2 / 2**9,
        ("brakes", "inactive"): 2 * 2 / 2**6,
        ("inactive", "random"): 2 / 2**3,
    }
    for pair, cell in cells.items():
        a, b = pair
        diff = 100 * (COLLIDES[a].stop - COLLIDES[b].stop) / EPISODES
        assert float(cell["diff"]) == pytest.approx(round(diff, 1))
        assert float(cell["p"]) == pytest.approx(p[pair], rel=1e-5)
        assert float(cell["p-holm"]) == pytest.approx(by_hand[pair], rel=1e-5)
        assert cell["significant"] == ("yes" if by_hand[pair] <= 0.05 else "no")
    assert cells[("brakes", "random")]["text"].startswith("-75.0*")  # significant, marked
    assert cells[("brakes", "inactive")]["text"].startswith("-50.0 ")  # p 0.031 < 5%, but not after Holm


def test_pairs_are_ordered_and_signed_as_compare_prints_them(known):
    c = compare_runs([known])  # as `rmm-bench compare DIR`: every stored agent
    raw = (known / "results.html").read_text(encoding="utf-8")
    for outcome in ("goal", "collision", "timeout"):
        cells = _cells(known / "results.html", outcome)
        rows = c.pairs[c.pairs.outcome == outcome]
        assert list(cells) == [(r.a, r.b) for r in rows.itertuples()]  # the upper triangle, in compare's order
        for r in rows.itertuples():
            assert float(cells[(r.a, r.b)]["diff"]) == pytest.approx(round(100 * r.diff, 1))
    details = re.findall(r"<table class='pair' data-a='([^']*)' data-b='([^']*)'>", raw)
    assert details == list(dict.fromkeys((r.a, r.b) for r in c.pairs.itertuples()))
    assert "<table class='pairs'>" not in raw  # no row per pair and outcome
    assert raw.count("<details class='pair'>") == 3 and "<details open" not in raw


def test_constant_columns_move_to_the_provenance(known):
    page = _parse(known / "results.html")
    head = page.rows["table-i"][0]
    assert "Policy compute time [ms]" not in head and "Obstacles" not in head and "Episodes" not in head
    assert "Success rate [% eps]" in head and "Collision rate [% eps]" in head
    constant = {r[0]: r[1] for r in page.rows["constant"][1:]}
    assert constant["Policy compute time [ms]"] == "1.00 ± 0.00"  # a fixed clock charges every step alike
    assert constant["Obstacles"] == "5" and constant["Episodes"] == str(EPISODES)
    md = [ln for ln in (known / "table_I.md").read_text().splitlines() if ln.startswith("| ")]
    assert "Policy compute time [ms]" in md[0]  # the printed and stored tables keep every column


def test_a_third_party_counter_is_a_column_of_the_page_and_the_csv(tmp_path):
    out = tmp_path / "c"
    agent = "tests.bench_helpers:Counting"
    assert main(["--agent", f"{agent},cbf", "--episodes", "3", *FIXED, "--out", str(out)]) == 0
    with sqlite3.connect(out / "results.db") as db:
        stored = [json.loads(s) for (s,) in db.execute("SELECT guardian_stats FROM episodes WHERE agent = ?", (agent,))]
    total = sum(s["decisions"] for s in stored)
    assert total > 0
    with open(out / "table_I.csv", newline="") as f:
        rows = {r["agent"]: r for r in csv.DictReader(f)}
    assert rows[agent]["stats.decisions"] == str(total) and rows["cbf"]["stats.decisions"] == ""
    assert rows["cbf"]["stats.qp_solves"] != "" and rows[agent]["stats.qp_solves"] == ""  # built-in's too
    assert main(["report", str(out), "--html"]) == 0
    page = _parse(out / "results.html")
    head, *body = page.rows["counters"]
    table = {r[0]: dict(zip(head, r, strict=True)) for r in body}
    assert table[agent]["decisions"] == str(total) and table["cbf"]["decisions"] == "—"
    assert table["cbf"]["qp_fallbacks"] == rows["cbf"]["stats.qp_fallbacks"]


def test_report_shows_every_agent_of_the_newest_configuration(tmp_path, capsys):
    out = tmp_path / "inv"
    for agents, seed in (("inactive", "0"), ("brakes", "0"), ("inactive", "0"), ("random", "1")):
        assert (
            main(["--agent", agents, "--episodes", "2", "--seed", seed, *FIXED, "--no-figure", "--out", str(out)]) == 0
        )
    capsys.readouterr()

    def agents(argv) -> list[str]:
        assert main(["report", str(out), *argv]) == 0
        text = capsys.readouterr().out.split("For comparison")[0]
        return [ln.split("|")[1].strip() for ln in text.splitlines() if ln.startswith("| ") and "Agent" not in ln]

    assert agents([]) == ["random"]  # the newest configuration: seed 1
    assert agents(["--invocation", "1", "--invocation", "2", "--invocation", "3"]) == ["inactive", "brakes"]
    assert agents(["--invocation", "2"]) == ["brakes"]
    assert main(["--agent", "brakes", "--episodes", "2", "--seed", "0", *FIXED, "--no-figure", "--out", str(out)]) == 0
    capsys.readouterr()
    assert agents([]) == ["inactive", "brakes"]  # seed 0 again: every agent stored under it, once each


def test_replays_over_the_page_budget_are_listed_not_embedded(known, tmp_path, monkeypatch):
    copy = tmp_path / "r"
    shutil.copytree(known, copy)
    (copy / "replays").mkdir()
    gif = b"GIF89a" + bytes(20_000)
    for name in ("a-episode-1.gif", "b-episode-2.gif"):
        (copy / "replays" / name).write_bytes(gif)
    html_size = len((known / "results.html").read_bytes())
    monkeypatch.setattr(rmm_bench.html, "PAGE_LIMIT", html_size + 40_000)  # room for one of the two
    assert main(["report", str(copy), "--html"]) == 0
    page = _parse(copy / "results.html")
    gifs = [a["src"] for t, a in page.attrs if t == "img" and a["src"].startswith("data:image/gif")]
    text = "".join(page.text)
    assert len(gifs) == 1 and "b-episode-2.gif (0.0 MB, over the page's" in text
    assert (copy / "results.html").stat().st_size < html_size + 40_000


def test_the_reference_results_page_is_current():
    from rmm_bench.reference_page import COMMAND, PAGE, render

    docs = ROOT / "docs"
    text = (docs / PAGE).read_text()
    assert text == render(), f"docs/{PAGE} is stale: run {COMMAND}"
    assert f"generated by `{COMMAND}`" in text[:600]  # generated: not counted as hand-written prose
    for figure in re.findall(r"\]\((figures/reference_\w+\.png)\)", text):
        assert (docs / figure).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (docs / figure).stat().st_size < 100_000
    assert "(reference-results.md)" in (docs / "index.md").read_text()
