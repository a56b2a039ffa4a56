"""Agent names in tables and messages (:mod:`rmm_bench.names`): escaped in every table format,
read back intact, and "did you mean" under a typo in compare, export and replay."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_bench.cli import main
from rmm_bench.names import did_you_mean, md_cell, md_cells, tex_cell
from rmm_bench.report import format_tables


@settings(max_examples=300, deadline=None)
@given(st.lists(st.text(alphabet=st.sampled_from("ab |\\`<>&\n\r*_ "), max_size=12), min_size=1, max_size=4))
def test_a_markdown_row_reads_back_cell_by_cell(cells):
    cells = [c.strip() for c in cells]  # a cell's own outer blanks are the row's padding
    line = "| " + " | ".join(md_cell(c) for c in cells) + " |"
    assert "\n" not in line and "\r" not in line
    assert md_cells(line) == [c.replace("\r\n", "\n").replace("\r", "\n") for c in cells]


def test_markdown_and_latex_escapes_by_hand():
    assert md_cell("a|b") == r"a\|b" and md_cell("x\\") == "x\\\\" and md_cell("a\nb") == "a<br>b"
    assert md_cell("<br>") == r"\<br>" and md_cells(r"| \<br> | a<br>b |") == ["<br>", "a\nb"]
    assert md_cell("lrmm-paper") == "lrmm-paper" and md_cell("mypkg.guard:My_Guard") == "mypkg.guard:My_Guard"
    assert tex_cell("my_guard 5% & {x} $y #1 ~^\\|<>") == (
        r"my\_guard 5\% \& \{x\} \$y \#1 \textasciitilde{}\textasciicircum{}\textbackslash{}\textbar{}"
        r"\textless{}\textgreater{}"
    )
    assert tex_cell("a\nb") == "a b"


def test_did_you_mean():
    assert did_you_mean("lrm", ["cbf", "lrmm", "lrmm-paper"]) == " (did you mean 'lrmm'?)"
    assert did_you_mean("zzz", ["cbf", "lrmm"]) == ""


def _row(agent: str) -> dict:
    nan = float("nan")
    return {
        "agent": agent, "obs": "local", "n_obst": 5, "episodes": 8, "compute_ms": (1.0, 0.5), "goal": (50.0, 1.0),
        "collision": (25.0, 1.0), "timeout": (25.0, 1.0), "intervention": (10.0, 1.0), "errors": 0,
        "qp_fallbacks": 0, "precompute_s": (nan, nan),
    }  # fmt: skip


def test_table_i_keeps_its_columns_whatever_the_name():
    tables = format_tables([_row("a|b"), _row("my_guard%\nv2")])
    md = [ln for ln in tables["md"].splitlines() if ln.startswith("|")]
    assert {len(md_cells(ln)) for ln in md} == {len(md_cells(md[0]))}
    assert [md_cells(ln)[0] for ln in md[2:]] == ["a|b", "my_guard%\nv2"]
    tex = tables["tex"].splitlines()
    assert tex[2].startswith(r"a\textbar{}b & ") and tex[3].startswith(r"my\_guard\% v2 & ")


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("names") / "run"
    argv = ["--agent", "inactive,random", "--episodes", "2", "--clock", "fixed:1", "--workers", "1", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["compare", "{run}", "--agent", "inactiv,random"], "no run of 'inactiv' is stored (did you mean 'inactive'?)"),
        (["export", "{run}", "--agent", "randm", "--table", "{tmp}/x.csv", "--format", "csv"], "(did you mean 'random'?)"),
        (["replay", "{run}", "--agent", "inactve", "--episode", "0"], "(did you mean 'inactive'?)"),
    ],
)  # fmt: skip
def test_an_agent_typo_gets_did_you_mean(run, tmp_path, capsys, argv, expected):
    assert main([a.format(run=run, tmp=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1
