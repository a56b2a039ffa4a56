"""``rmm-bench compare`` and the results page show errored episodes (issue 49): an episode whose
guardian raised is its own ``error`` row with a note, the outcome tests run over the episodes
where neither agent errored, and an agent that errored in every episode gets no test at all."""

from __future__ import annotations

import math
import shutil
import sqlite3

import pandas as pd
import pytest

from rmm_bench import load_results
from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.paired import mcnemar_exact

BOOM = "tests.bench_helpers:Boom"  # raises in its third decision: every episode errors
EPISODES = 16


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("errors") / "run"
    argv = ["--agent", f"{BOOM},inactive,random", "--episodes", str(EPISODES), "--clock", "fixed:1", "--workers", "1"]
    assert main([*argv, "--no-progress", "--out", str(out)]) == 1  # 1: a guardian raised
    return out


def _errored(run, tmp_path, agent: str, episodes: tuple[int, ...]):
    """A copy of ``run`` where ``agent``'s guardian raised in ``episodes``."""
    copy = tmp_path / "copy"
    shutil.copytree(run, copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute(
            "UPDATE episodes SET outcome = 'error', error_kind = 'guardian', error = 'RuntimeError: boom' "
            f"WHERE agent = ? AND episode IN ({','.join('?' * len(episodes))})",
            (agent, *episodes),
        )
    return copy


def test_an_agent_that_errored_in_every_episode_gets_its_row_and_a_note_but_no_test(run, capsys):
    c = compare_runs([run], [BOOM, "inactive"], resamples=50)
    (row,) = c.pairs.itertuples()  # before: goal, collision, timeout rows with p-values, no error row
    assert (row.outcome, row.n, row.rate_a, row.rate_b) == ("error", EPISODES, 1.0, 0.0)
    assert (row.a_only, row.b_only, row.both) == (EPISODES, 0, 0) and math.isnan(row.p_value)
    assert row.a_only_episodes == [0, 1, 2, 3, 4]
    assert len(c.continuous) == 0  # nothing to compare either
    note = (
        f"Dubins4DParallel-v0 seed 0 clock fixed:1: {BOOM} vs inactive: no outcome test, as there is no episode "
        f"where neither errored; {BOOM} errored in all {EPISODES} (episodes 0, 1, 2, 3, 4 and 11 more)"
    )
    assert note in c.notes and len(c.floor) == 0
    assert main(["compare", str(run), "--agent", f"{BOOM},inactive"]) == 0
    out = capsys.readouterr().out
    rows = [ln for ln in out.splitlines() if ln.startswith(f"| {BOOM} |")]
    assert rows == [f"| {BOOM} | inactive | error | 16 | 100.0 | 0.0 | — | 16 | 0 | 0 | — | 0,1,2,3,4 (+11) |  |"]
    assert f"Note: {note}" in out
    assert main(["compare", str(run), "--agent", f"{BOOM},inactive", "--format", "csv"]) == 0
    table = pd.read_csv(pd.io.common.StringIO(capsys.readouterr().out))
    assert list(table.outcome) == ["error"] and table.note.item() == note.split(": ", 1)[1]


def test_outcome_tests_run_over_the_episodes_where_neither_errored(run, tmp_path, capsys):
    copy = _errored(run, tmp_path, "inactive", (3, 7))
    df = load_results(copy)
    c = compare_runs([copy], ["inactive", "random"], resamples=50)
    tested = [e for e in range(EPISODES) if e not in (3, 7)]
    outcome_rows = c.pairs[c.pairs.outcome.isin(["goal", "collision", "timeout"])]
    assert list(outcome_rows.n) == [len(tested)] * 3  # before: all 16, errors counted as no outcome
    for r in outcome_rows.itertuples():
        a = df[(df.agent == "inactive") & df.episode.isin(tested)].set_index("episode").outcome == r.outcome
        b = df[(df.agent == "random") & df.episode.isin(tested)].set_index("episode").outcome == r.outcome
        assert (r.both, r.a_only, r.b_only) == (int((a & b).sum()), int((a & ~b).sum()), int((~a & b).sum()))
        assert r.p_value == mcnemar_exact(r.a_only, r.b_only)
        assert not set(r.a_only_episodes) & {3, 7} and not set(r.b_only_episodes) & {3, 7}
    (err,) = c.pairs[c.pairs.outcome == "error"].itertuples()
    assert (err.n, err.a_only, err.b_only, err.a_only_episodes) == (EPISODES, 2, 0, [3, 7])
    assert err.rate_a == 2 / EPISODES and math.isnan(err.diff)
    note = "inactive vs random: outcome tests over the 14 episodes where neither errored; inactive errored in 2 (episodes 3, 7)"
    assert set(c.pairs.note) == {note} and f"Dubins4DParallel-v0 seed 0 clock fixed:1: {note}" in c.notes
    # the continuous columns too: an errored episode's decision time is not the guardian's
    assert dict(zip(c.continuous.column, c.continuous.n, strict=True))["decision_ms"] == len(tested)
    # and the floor: a guardian that raised did not fail there
    assert not set(c.floor.episode) & {3, 7} and any("floor leaves out" in n for n in c.notes)


def test_unpaired_rates_leave_errors_out_and_say_so(run, tmp_path):
    copy = _errored(run, tmp_path, "random", (0, 1, 2, 3))
    c = compare_runs([copy], ["inactive", "random"], unpaired=True)
    goal = c.pairs[c.pairs.outcome == "goal"].iloc[0]
    assert (goal.n_a, goal.n_b) == (EPISODES, EPISODES - 4)
    err = c.pairs[c.pairs.outcome == "error"].iloc[0]
    assert (err.rate_a, err.rate_b) == (0.0, 4 / EPISODES)
    assert any("random errored in 4 of 16" in n for n in c.notes)
    only = compare_runs([run], [BOOM, "inactive"], unpaired=True)
    assert list(only.pairs.outcome) == ["error"] and any("no outcome test" in n for n in only.notes)


def test_the_page_shows_the_error_row_and_its_note(run, tmp_path):
    from tests.test_html import _parse

    page_path = tmp_path / "page.html"
    assert main(["report", str(run), "--html", str(page_path)]) == 0
    page = _parse(page_path)
    # compare orders the agents by name: inactive is A, the guardian that raised B
    ((_, rows),) = [(a, r) for a, r in page.tables if a.get("data-a") == "inactive" and a.get("data-b") == BOOM]
    assert [r[0] for r in rows[1:]] == ["error"]  # no test of an agent that never had an outcome
    assert rows[1][1:6] == ["16", "0.0", "100.0", "—", "—"] and rows[1][7].startswith("16: 0,1,2,3,4")
    assert f"inactive vs {BOOM}: no outcome test" in "".join(page.text)
    matrix = [r for a, r in page.tables if a.get("data-outcome") == "collision"][0]
    assert matrix[1][0] == "inactive" and matrix[1][-1] == "no test"  # its cell in the matrix says so
