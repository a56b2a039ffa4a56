"""rmm-bench ablation (rmm_bench.ablation): the rows of a system's ablation table come from the composition the guardian
reads; the paired column; the manifest it writes reads back (rmm_bench.manifest.table_manifest)."""

from __future__ import annotations

import pytest

from rmm_bench.ablation import _paired, variants
from rmm_bench.manifest import read_manifest, table_manifest


def test_dubins4d_rows_are_the_core_each_strategy_alone_and_the_full_guardian_minus_each():
    rows = variants("Dubins4DParallel-v0")
    assert [r[0] for r in rows] == [
        "driver alone (inactive)",
        "paper's rule (lrmm-paper)",
        "core: risk > threshold -> safe default",
        "core + SafestCandidate",
        "core + Commit",
        "core + Restart",
        "full guardian (lrmm): SafestCandidate, Commit, Restart",
        "full - SafestCandidate",
        "full - Commit",
        "full - Restart",
    ]
    assert [(a, o) for _, a, o in rows][2:] == [
        ("lrmm", {"strategies": ""}),
        ("lrmm", {"strategies": "SafestCandidate()"}),
        ("lrmm", {"strategies": "Commit(steps=18)"}),
        ("lrmm", {"strategies": "Restart(speed=0.3)"}),
        ("lrmm", {}),
        ("lrmm", {"strategies": "-SafestCandidate"}),
        ("lrmm", {"strategies": "-Commit"}),
        ("lrmm", {"strategies": "-Restart"}),
    ]


def test_a_variant_equal_to_an_earlier_one_is_one_row_with_both_labels():
    # the maze: one strategy, so the core plus it is the full guardian and the full minus it the core
    rows = variants("Dubins3DMazeParallel-v0")
    assert rows == [
        ("driver alone (inactive)", "inactive", {}),
        ("core: risk > threshold -> safe default (= full - Commit)", "lrmm", {"strategies": ""}),
        ("core + Commit (= full guardian (lrmm): Commit)", "lrmm", {}),  # run as the full guardian
    ]
    # no strategies at all: the core is the full guardian; the paper's rule only where it is served
    assert variants("CartPoleParallel-v0") == [
        ("driver alone (inactive)", "inactive", {}),
        ("core: risk > threshold -> safe default (= full guardian (lrmm): no strategies)", "lrmm", {}),
    ]


def test_the_paired_column_is_newcombes_interval_and_mcnemars_p_of_the_discordant_episodes():
    # 10 episodes: a collides in 0-3, b in 2-3 -> 2 discordant, both a's: +20 pp, p = 2 * 0.5^2 = 0.5
    a = {e: e < 4 for e in range(10)}
    b = {e: 2 <= e < 4 for e in range(10)}
    assert _paired(a, b) == ["+20.0 [-11.4, +47.1]", "0.5"]
    assert _paired(b, b) == ["+0.0 [-23.6, +23.6]", "1"]  # no discordant episode
    # only the common episodes count: 5 of them, a collides in 4, b in 2
    assert _paired(a, {e: v for e, v in b.items() if e < 5}) == ["+40.0 [-16.3, +72.6]", "0.5"]


def test_a_written_table_manifest_reads_back(tmp_path):
    fields = {
        "name": "t",
        "title": 'a "quoted" title, ± and —',
        "section": "S",
        "commands": ["rmm-bench ablation --seed 5"],
        "measured": "2026-12-04",
        "header": ["variant", "Success [%]", "Collision [%]", "Timeout [%]"],
        "rows": [["core", "50.0 ± 1.0", "20.0 ± 1.0", "30.0 ± 1.0"]],
    }
    check = {
        "agents": ["lrmm"],
        "rates": {"Success [%]": "goal", "Collision [%]": "collision", "Timeout [%]": "timeout"},
        "commands": ["rmm-bench --agent lrmm --agent-opt 'lrmm.strategies=\"\"' --episodes 4 --seed 5 --clock fixed:1"],
    }
    quick = [["--agent", "lrmm", "--agent-opt", 'lrmm.strategies=""', "--episodes", "4"]]
    path = tmp_path / "t.toml"
    path.write_text(table_manifest(fields, check, quick))
    m = read_manifest(path)
    assert (m.name, m.title, m.header, m.rows) == ("t", fields["title"], fields["header"], fields["rows"])
    assert m.quick_commands == quick and m.check["agents"] == ["lrmm"]


@pytest.mark.parametrize("bad", ["--episodes", "0"])
def test_bad_episode_counts_exit_2(bad, capsys):
    from rmm_bench.cli import main

    if bad == "0":
        assert main(["ablation", "--episodes", "0", "--out", "unused"]) == 2
        assert capsys.readouterr().err == "rmm-bench ablation: error: --episodes must be >= 1, got 0\n"
    else:
        with pytest.raises(SystemExit) as e:
            main(["ablation", "--episodes"])
        assert e.value.code == 2


def test_concordance_counts_the_four_kinds_of_paired_episode():
    from rmm_bench.paired import concordance

    assert concordance([1, 1, 0, 0, 1], [1, 0, 1, 0, 1]) == (2, 1, 1, 1)
    assert concordance([], []) == (0, 0, 0, 0)
