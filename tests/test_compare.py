"""``rmm-bench compare``: the paired statistics against hand computations and scipy, and the
command on real small runs (pairing across directories, refusals, reference results)."""

from __future__ import annotations

import math
import shutil
import sqlite3

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import binomtest

from rmm_bench import load_results
from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.paired import mcnemar_exact, newcombe_paired, newcombe_unpaired, paired_bootstrap
from rmm_bench.store import ResultsStore

Z = 1.959963984540054


def _wilson(x, n):
    p = x / n
    centre = (2 * x + Z * Z) / (2 * (n + Z * Z))
    half = Z * math.sqrt(x * (n - x) / n + Z * Z / 4) / (n + Z * Z)
    return p, max(0.0, centre - half), min(1.0, centre + half)


def test_newcombe_paired_by_hand():
    # 100 episodes: both fail 5, A alone 8, B alone 2, neither 85
    pa, la, ua = _wilson(13, 100)
    pb, lb, ub = _wilson(7, 100)
    # phi: (5 * 85 - 8 * 2) = 409 > n / 2 = 50, so 409 - 50 over sqrt(13 * 87 * 7 * 93)
    phi = 359 / math.sqrt(13 * 87 * 7 * 93)
    low = 0.06 - math.sqrt((pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2)
    high = 0.06 + math.sqrt((ua - pa) ** 2 - 2 * phi * (ua - pa) * (pb - lb) + (pb - lb) ** 2)
    d, lo, hi = newcombe_paired(5, 8, 2, 85)
    assert d == pytest.approx(0.06, abs=1e-15)
    assert lo == pytest.approx(low, abs=1e-12) and hi == pytest.approx(high, abs=1e-12)


def test_newcombe_paired_phi_zero_between_zero_and_half_n():
    # both * neither - a_only * b_only = 10 * 10 - 9 * 9 = 19 <= n / 2 = 19: phi is 0, the
    # interval is the square-and-add of the margins' Wilson intervals
    d, lo, hi = newcombe_paired(10, 9, 9, 10)
    p, lw, up = _wilson(19, 38)
    assert (
        d == 0 and lo == pytest.approx(-math.hypot(p - lw, up - p)) and hi == pytest.approx(math.hypot(up - p, p - lw))
    )


def test_newcombe_unpaired_by_hand():
    pa, la, ua = _wilson(56, 70)
    pb, lb, ub = _wilson(48, 80)
    d, lo, hi = newcombe_unpaired(56, 70, 48, 80)
    assert d == pytest.approx(0.2)
    assert lo == pytest.approx(0.2 - math.hypot(pa - la, ub - pb)) and hi == pytest.approx(
        0.2 + math.hypot(ua - pa, pb - lb)
    )
    # Newcombe's (1998) example 56/70 vs 48/80: method 10 gives 0.0524 to 0.3339
    assert lo == pytest.approx(0.0524, abs=1e-4) and hi == pytest.approx(0.3339, abs=1e-4)


def test_mcnemar_exact_by_hand():
    assert mcnemar_exact(3, 0) == pytest.approx(2 * 0.5**3)
    assert mcnemar_exact(5, 1) == pytest.approx(2 * (1 + 6) / 64)
    assert mcnemar_exact(4, 4) == 1.0 and mcnemar_exact(0, 0) == 1.0


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=400))
def test_paired_statistics_against_scipy_on_random_paired_data(pairs):
    a = np.array([p[0] for p in pairs])
    b = np.array([p[1] for p in pairs])
    both, a_only = int((a & b).sum()), int((a & ~b).sum())
    b_only, neither = int((~a & b).sum()), int((~a & ~b).sum())
    m = a_only + b_only
    p = mcnemar_exact(a_only, b_only)
    assert p == (binomtest(a_only, m, 0.5).pvalue if m else 1.0)
    d, lo, hi = newcombe_paired(both, a_only, b_only, neither)
    assert d == pytest.approx(a.mean() - b.mean(), abs=1e-12)
    assert -1.0 <= lo <= d + 1e-12 and d - 1e-12 <= hi <= 1.0
    d2, lo2, hi2 = newcombe_paired(both, b_only, a_only, neither)  # A and B swapped
    assert d2 == pytest.approx(-d, abs=1e-12) and lo2 == pytest.approx(-hi) and hi2 == pytest.approx(-lo)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 50), st.integers(1, 50), st.integers(0, 50), st.integers(1, 50))
def test_newcombe_unpaired_properties(xa, na, xb, nb):
    xa, xb = min(xa, na), min(xb, nb)
    d, lo, hi = newcombe_unpaired(xa, na, xb, nb)
    assert -1.0 <= lo <= d + 1e-12 <= hi + 2e-12 <= 1.0 + 2e-12
    d2, lo2, hi2 = newcombe_unpaired(xb, nb, xa, na)
    assert d2 == pytest.approx(-d) and lo2 == pytest.approx(-hi) and hi2 == pytest.approx(-lo)


def test_paired_bootstrap_is_deterministic_under_its_seed():
    rng = np.random.default_rng(3)
    x, y = rng.normal(1.0, 1.0, 300), rng.normal(0.0, 1.0, 300)
    first = paired_bootstrap(x, y, seed=7, resamples=500)
    assert first == paired_bootstrap(x, y, seed=7, resamples=500)
    assert first != paired_bootstrap(x, y, seed=8, resamples=500)
    d, lo, hi = first
    assert d == pytest.approx(float(np.mean(x - y))) and lo < d < hi
    # a constant difference has no spread
    assert paired_bootstrap(np.full(20, 3.0), np.full(20, 1.0), resamples=50) == (2.0, 2.0, 2.0)
    assert all(math.isnan(v) for v in paired_bootstrap(np.array([]), np.array([])))


# ---------------------------------------------------------------- real runs

EPISODES = 24


def _run(out, agents, seed=0, episodes=EPISODES):
    code = main(
        ["--agent", agents, "--episodes", str(episodes), "--clock", "fixed:1", "--seed", str(seed), "--workers", "1",
         "--out", str(out), "--no-progress"]
    )  # fmt: skip
    assert code == 0


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("compare")
    _run(root / "all", "lrmm,cbf,inactive")
    _run(root / "a", "lrmm")
    _run(root / "b", "cbf,inactive")
    _run(root / "seed1", "cbf", seed=1)
    return root


def _by_hand(df, a, b, outcome):
    ea = df[df.agent == a].set_index("episode")["outcome"] == outcome
    eb = df[df.agent == b].set_index("episode")["outcome"] == outcome
    return int((ea & eb).sum()), int((ea & ~eb).sum()), int((~ea & eb).sum()), int((~ea & ~eb).sum())


def _doomed(run) -> dict[int, bool]:
    from rmm_envs.starts import world_key

    cfg = load_results(run).config.iloc[0]
    store = ResultsStore(run / "results.db", read_only=True)
    try:
        return {
            e: s["doomed"] for e, s in store.starts(world_key(cfg["env_id"], cfg["env_kwargs"], cfg["seed"])).items()
        }
    finally:
        store.close()


def test_counts_match_the_stored_rows(runs):
    df = load_results(runs / "all")
    doomed = _doomed(runs / "all")
    c = compare_runs([runs / "all"], ["lrmm", "cbf", "inactive"], resamples=200)
    assert c.paired and list(c.agents) == ["lrmm", "cbf", "inactive"]
    assert set(zip(c.pairs.a, c.pairs.b, strict=True)) == {("lrmm", "cbf"), ("lrmm", "inactive"), ("cbf", "inactive")}
    for r in c.pairs.itertuples():
        rows = df if r.outcome != "avoidable collision" else df[~df.episode.map(doomed)]
        outcome = "collision" if r.outcome == "avoidable collision" else r.outcome
        assert (r.both, r.a_only, r.b_only, r.neither) == _by_hand(rows, r.a, r.b, outcome)
        assert r.n == rows.episode.nunique() and r.p_value == mcnemar_exact(r.a_only, r.b_only)
        assert len(r.a_only_episodes) == min(5, r.a_only)
        for e in r.a_only_episodes:  # ready for replay: A had the outcome there, B did not
            assert df[(df.agent == r.a) & (df.episode == e)].outcome.item() == outcome
            assert df[(df.agent == r.b) & (df.episode == e)].outcome.item() != outcome
    assert set(c.pairs.outcome) == {"goal", "collision", "timeout", "avoidable collision"}
    # the floor: every agent failed there
    failed = df.groupby("episode").outcome.apply(lambda s: "goal" not in set(s))
    assert sorted(c.floor.episode) == sorted(failed[failed].index)
    assert list(c.floor.doomed) == [doomed[e] for e in c.floor.episode]
    assert not any("not assessed" in n for n in c.notes)


def test_agents_in_two_directories_pair_as_in_one(runs):
    one = compare_runs([runs / "all"], ["lrmm", "cbf"], resamples=100)
    two = compare_runs([runs / "a", runs / "b"], ["lrmm", "cbf"], resamples=100)
    cols = ["outcome", "n", "both", "a_only", "b_only", "neither", "p_value", "lo", "hi"]
    assert one.pairs[cols].equals(two.pairs[cols])
    reproducible = one.continuous.column != "decision_ms"  # a measured time differs between runs
    assert one.continuous[reproducible][["column", "n", "diff", "lo", "hi"]].equals(
        two.continuous[reproducible][["column", "n", "diff", "lo", "hi"]]
    )


def test_a_different_seed_is_refused_naming_the_key(runs, capsys):
    assert main(["compare", str(runs / "a"), str(runs / "seed1"), "--agent", "lrmm,cbf"]) == 2
    err = capsys.readouterr().err
    assert "ran no episode alike" in err and "seed 0" in err and "seed 1" in err and "--unpaired" in err
    # unpaired, it compares
    assert main(["compare", str(runs / "a"), str(runs / "seed1"), "--agent", "lrmm,cbf", "--unpaired"]) == 0
    assert "unpaired" in capsys.readouterr().out


def test_an_edited_start_is_refused_naming_the_episode(runs, tmp_path, capsys):
    copy = tmp_path / "b"
    shutil.copytree(runs / "b", copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute("UPDATE episodes SET start = 'ffffffffffffffff' WHERE agent = 'cbf' AND episode = 7")
    assert main(["compare", str(runs / "a"), str(copy), "--agent", "lrmm,cbf"]) == 2
    err = capsys.readouterr().err
    assert "episode 7 started differently" in err and "ffffffffffffffff" in err


def test_rows_without_fingerprints_pair_only_within_one_database(runs, tmp_path, capsys):
    copy = tmp_path / "b"
    shutil.copytree(runs / "b", copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute("UPDATE episodes SET start = NULL")
    assert compare_runs([copy], ["cbf", "inactive"], resamples=10).pairs.n.iloc[0] == EPISODES
    assert main(["compare", str(runs / "a"), str(copy), "--agent", "lrmm,cbf"]) == 2
    assert "no start fingerprint" in capsys.readouterr().err


def test_starts_not_assessed_give_no_avoidable_row(runs, tmp_path):
    copy = tmp_path / "all"
    shutil.copytree(runs / "all", copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute("UPDATE starts SET doomed = NULL WHERE episode = 3")
    c = compare_runs([copy], ["lrmm", "cbf"], resamples=10)
    assert "avoidable collision" not in set(c.pairs.outcome)
    assert any("starts not assessed" in n for n in c.notes)


def test_csv_and_markdown_outputs(runs, tmp_path, capsys):
    out = tmp_path / "cmp.csv"
    assert main(["compare", str(runs / "all"), "--agent", "lrmm,cbf", "--format", "csv", "--table", str(out)]) == 0
    import pandas as pd

    table = pd.read_csv(out)
    assert list(table.outcome) == ["goal", "collision", "timeout", "avoidable collision"] and set(table.a) == {"lrmm"}
    assert (
        main(["compare", str(runs / "all"), "--agent", "lrmm,cbf", "--resamples", "50", "--bootstrap-seed", "3"]) == 0
    )
    text = capsys.readouterr().out
    assert "| lrmm | cbf | collision |" in text and "seed 3, 50 resamples" in text and "Floor:" in text


def test_reference_results_pair_with_a_new_run(runs, tmp_path, monkeypatch, capsys):
    shipped = tmp_path / "shipped"
    shipped.mkdir()
    shutil.copy(runs / "b" / "results.db", shipped / "dubins4d.db")
    monkeypatch.setenv("RMM_REFERENCE_DIR", str(shipped))
    c = compare_runs([runs / "a"], ["lrmm"], reference=True, resamples=10)
    assert set(c.agents) == {"lrmm", "ref:cbf", "ref:inactive"}
    same = compare_runs([runs / "all"], ["lrmm", "cbf"], resamples=10)
    got = c.pairs[(c.pairs.b == "ref:cbf")].reset_index(drop=True)
    assert got[["both", "a_only", "b_only"]].equals(same.pairs[["both", "a_only", "b_only"]])
    # a run of other episodes finds no reference
    assert main(["compare", str(runs / "seed1"), "--reference"]) == 2
    assert "no shipped reference result" in capsys.readouterr().err
    # naming reference agents chooses them (before: every shipped one was added)
    chosen = compare_runs([runs / "a"], ["lrmm", "ref:cbf"], reference=True, resamples=10)
    assert chosen.agents == ["lrmm", "ref:cbf"] and set(zip(chosen.pairs.a, chosen.pairs.b, strict=True)) == {
        ("lrmm", "ref:cbf")
    }
    assert main(["compare", str(runs / "a"), "--reference", "--agent", "lrmm,ref:cbf", "--resamples", "10"]) == 0
    assert "ref:inactive" not in capsys.readouterr().out
    assert main(["compare", str(runs / "a"), "--reference", "--agent", "lrmm,ref:cbff"]) == 2
    assert "(did you mean 'ref:cbf'?)" in capsys.readouterr().err


def test_a_run_no_other_agent_ran_alike_is_named_in_one_line(runs, capsys):
    dirs = [str(runs / d) for d in ("a", "b", "seed1")]
    assert main(["compare", *dirs, "--agent", "lrmm,cbf", "--resamples", "10"]) == 0
    err = capsys.readouterr().err  # before: cbf's seed-1 run left out without a word
    assert err.count("\n") == 1 and "left out" in err and "cbf (Dubins4DParallel-v0 seed 1" in err
    assert str(runs / "seed1") in err
    c = compare_runs([runs / "a", runs / "b", runs / "seed1"], ["lrmm", "cbf"], resamples=10)
    assert len(c.left_out) == 1 and set(c.pairs.group) == {"Dubins4DParallel-v0 seed 0 clock fixed:1"}
    # every run paired: nothing said
    assert compare_runs([runs / "a", runs / "b"], ["lrmm", "cbf"], resamples=10).left_out == []


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["compare", "{root}/missing", "--agent", "lrmm,cbf"], "does not exist"),
        (["compare", "{root}", "--agent", "lrmm,cbf"], "holds no results.db"),
        (["compare", "{root}/all", "--agent", "lrmm,nope"], "no run of 'nope'"),
        (["compare", "{root}/all", "--agent", "lrmm"], "at least two agents"),
        (["compare", "{root}/all", "--format", "xml"], "expected md or csv"),
        (["compare", "{root}/all", "--resamples", "0"], "--resamples must be >= 1"),
        (["compare", "{root}/all", "--agent", ","], "expected one agent name or a comma list"),
        (["compare", "{root}/all", "--agent", "lrmm@zzzz,cbf"], "whose key starts with 'zzzz'"),
        (["compare", "{root}/all", "--agent", "lrm,cbf"], "no run of 'lrm' is stored (did you mean 'lrmm'?)"),
        (["compare", "{root}/all", "--agent", "lrmm,ref:cbf"], "are compared with --reference"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(runs, capsys, args, expected):
    assert main([a.format(root=runs) for a in args]) == 2
    err = capsys.readouterr().err
    assert expected in err and err.count("\n") == 1


def test_a_newer_schema_is_refused(runs, tmp_path, capsys):
    copy = tmp_path / "all"
    shutil.copytree(runs / "all", copy)
    with sqlite3.connect(copy / "results.db") as db:
        db.execute("PRAGMA user_version = 99")
    assert main(["compare", str(copy), "--agent", "lrmm,cbf"]) == 2
    assert "schema version 99" in capsys.readouterr().err


def test_compare_never_writes_its_inputs(runs, tmp_path):
    copy = tmp_path / "all"
    shutil.copytree(runs / "all", copy)
    before = {p.name: p.read_bytes() for p in copy.iterdir()}
    compare_runs([copy], resamples=10)
    assert {p.name: p.read_bytes() for p in copy.iterdir()} == before
