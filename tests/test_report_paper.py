"""The paper's Table I beside ours: labelled as the paper's, its figures as the paper printed them,
``—`` where it gave none."""

from rmm_bench.cli import main
from rmm_bench.report import NOT_REPORTED, PAPER_LABEL, PAPER_TABLE_I, format_paper_table

RUN = ["--clock", "fixed:1", "--no-progress", "--no-figure", "--env", "Dubins4DParallel-v0"]

# Table I of the paper (Allen, Xiao, Rus, ICRA 2023): agent, observation, obstacles, compute time,
# success, collision, timeout and intervention rates, as printed there
PAPER = {
    "lrmm": ("local", "5", "2.4 ± 5.0", "45.3 ± 7.3", "29.7 ± 5.6", "25.0 ± 4.8", "30.7 ± 32.5"),
    "cbf": ("global", "5", "52.9 ± 41.2", "46.2 ± 5.9", "35.1 ± 5.2", "18.8 ± 3.8", "32.8 ± 39.4"),
    "random": ("none", "5", "1.4 ± 2.7", "27.1 ± 6.9", "68.4 ± 5.9", "4.5 ± 2.9", "~50"),
    "inactive": ("none", "5", "1.0 ± 2.3", "44.4 ± 7.4", "55.4 ± 7.3", "0.1 ± 0.5", "0"),
    "brakes": ("none", "5", "0.3 ± 0.7", "0.6 ± 0.9", "9.0 ± 3.8", "90.4 ± 3.7", "100"),
    "hj": ("global", "1", "344.0 ± 850.0", "54.0 ± 5.2", "46.0 ± 5.3", "0.0 ± 0.3", "<1.0"),
}


def _rows(md: str) -> dict[str, list[str]]:
    lines = [ln for ln in md.splitlines() if ln.startswith("| ") and not ln.startswith("| Agent")]
    return {cells[0]: cells[1:] for cells in ([c.strip() for c in ln.strip("|").split("|")] for ln in lines)}


def test_the_paper_rows_are_the_papers_labelled_with_a_dash_where_it_gave_no_figure():
    assert PAPER_LABEL == "paper, ICRA 2023" and NOT_REPORTED == "—"
    assert set(PAPER_TABLE_I) == set(PAPER)
    md = format_paper_table(list(PAPER))
    header = md.splitlines()[0]
    assert header.endswith("| Intervention rate [% steps] | Errors | QP fallbacks |")  # the paper's unit
    rows = _rows(md)
    assert list(rows) == [f"{a} (paper, ICRA 2023)" for a in PAPER]
    for agent, figures in PAPER.items():
        obs, n_obst, *rates = figures
        assert rows[f"{agent} (paper, ICRA 2023)"] == [obs, n_obst, "2048", *rates, "—", "—"]
    assert "—: the paper gave no figure" in md


def test_presets_map_to_the_papers_row_and_other_agents_have_none():
    rows = _rows(format_paper_table(["lrmm-paper", "cbf-paper", "mymodule:Mine", "inactive"]))
    assert list(rows) == ["lrmm (paper, ICRA 2023)", "cbf (paper, ICRA 2023)", "inactive (paper, ICRA 2023)"]
    assert list(_rows(format_paper_table(["lrmm", "lrmm-paper"]))) == ["lrmm (paper, ICRA 2023)"]  # one row
    assert format_paper_table(["mymodule:Mine"]) == ""


def test_the_report_labels_the_paper_rows_beside_ours(tmp_path, capsys):
    out = tmp_path / "p"
    assert main(["--agent", "lrmm,inactive", "--episodes", "1", "--workers", "1", "--out", str(out), *RUN]) == 0
    text = capsys.readouterr().out
    ours, paper = text.split("For comparison, the paper's Table I rows for these agents")
    assert "the paper's own implementations and LRMM model, not the guardians run here" in paper
    assert "for the same agents" not in text
    assert set(_rows(ours)) == {"lrmm", "inactive"}  # ours: measured here, with errors and QP fallbacks
    assert all(cells[-2:] == ["0", "0"] for cells in _rows(ours).values())
    rows = _rows(paper)
    assert list(rows) == ["lrmm (paper, ICRA 2023)", "inactive (paper, ICRA 2023)"]
    assert rows["lrmm (paper, ICRA 2023)"] == ["local", "5", "2048", *PAPER["lrmm"][2:], "—", "—"]
    # the tables written to disk are ours alone
    assert "paper" not in (out / "table_I.md").read_text().split("Rates:")[0]


def test_no_paper_rows_for_an_env_the_paper_did_not_evaluate(tmp_path, capsys):
    out = tmp_path / "m"
    args = ["--agent", "inactive", "--episodes", "1", "--workers", "1", "--out", str(out)]
    assert main([*args, "--clock", "fixed:1", "--no-progress", "--no-figure", "--env", "CartPoleParallel-v0"]) == 0
    text = capsys.readouterr().out
    assert "paper, ICRA 2023" not in text and "For comparison" not in text
