"""``compare``'s pairing and floor on outcomes set by hand: a small real run whose stored outcomes
and doomed flags are rewritten to a known pattern, so that every count of every pair, the
avoidable-collision rows and the floor can be written down (tests/test_compare.py checks the same
against real runs' rows)."""

from __future__ import annotations

import math
import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.paired import mcnemar_exact, newcombe_paired

AGENTS = ["random", "inactive", "brakes"]
#: each agent's outcome in episodes 0-7: Goal, Collision, Timeout
OUTCOMES = {"random": "GCCTCGCT", "inactive": "CCGTCCTC", "brakes": "CTCTCCCG"}
WORD = {"G": "goal", "C": "collision", "T": "timeout"}
DOOMED = [0, 1, 0, 0, 1, 0, 0, 1]


def _sql(db: Path, *statements) -> None:
    con = sqlite3.connect(db)
    try:
        for s in statements:
            con.execute(*s)
        con.commit()
    finally:
        con.close()


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("pairing") / "run"
    argv = ["--agent", ",".join(AGENTS), "--episodes", "8", "--clock", "fixed:1", "--workers", "1"]
    assert main([*argv, "--no-progress", "--no-figure", "--out", str(out)]) == 0
    edits = [
        ("UPDATE episodes SET outcome = ? WHERE agent = ? AND episode = ?", (WORD[o], agent, e))
        for agent, pattern in OUTCOMES.items()
        for e, o in enumerate(pattern)
    ]
    edits += [("UPDATE starts SET doomed = ? WHERE episode = ?", (d, e)) for e, d in enumerate(DOOMED)]
    _sql(out / "results.db", *edits)
    return out


def _row(c, a, b, outcome):
    (r,) = [r for r in c.pairs.itertuples() if (r.a, r.b, r.outcome) == (a, b, outcome)]
    return r


def _counts(r):
    return r.n, r.both, r.a_only, r.b_only, r.neither


def test_every_pair_counts_the_outcomes_by_hand(run):
    c = compare_runs([run], ["random", "inactive"], resamples=20)
    # episode:   0 1 2 3 4 5 6 7
    # random:    G C C T C G C T
    # inactive:  C C G T C C T C
    assert _counts(_row(c, "random", "inactive", "goal")) == (8, 0, 2, 1, 5)
    assert _counts(_row(c, "random", "inactive", "collision")) == (8, 2, 2, 3, 1)
    assert _counts(_row(c, "random", "inactive", "timeout")) == (8, 1, 1, 1, 5)
    # avoidable: the starts not doomed, 0 2 3 5 6: random collides in 2 and 6, inactive in 0 and 5
    assert _counts(_row(c, "random", "inactive", "avoidable collision")) == (5, 0, 2, 2, 1)
    r = _row(c, "random", "inactive", "collision")
    assert (r.rate_a, r.rate_b) == (0.5, 0.625)
    assert (r.diff, r.lo, r.hi) == newcombe_paired(2, 2, 3, 1) and r.p_value == mcnemar_exact(2, 3)
    assert r.a_only_episodes == [2, 6] and r.b_only_episodes == [0, 5, 7]
    r = _row(c, "random", "inactive", "avoidable collision")
    assert (r.rate_a, r.rate_b) == (0.4, 0.4) and r.a_only_episodes == [2, 6] and r.b_only_episodes == [0, 5]
    assert (r.diff, r.lo, r.hi) == newcombe_paired(0, 2, 2, 1) and r.p_value == mcnemar_exact(2, 2)
    r = _row(c, "random", "inactive", "goal")
    assert r.a_only_episodes == [0, 5] and r.b_only_episodes == [2] and r.p_value == mcnemar_exact(2, 1)
    assert list(c.pairs.outcome) == ["goal", "collision", "timeout", "avoidable collision"]
    assert set(c.pairs.group) == {"Dubins4DParallel-v0 seed 0 clock fixed:1"}


def test_the_pairs_of_three_agents_and_the_first_episodes_shown(run):
    c = compare_runs([run], AGENTS, resamples=20, show=1)
    assert [(r.a, r.b) for r in c.pairs.itertuples() if r.outcome == "goal"] == [
        ("random", "inactive"),
        ("random", "brakes"),
        ("inactive", "brakes"),
    ]
    # brakes:    C T C T C C C G
    assert _counts(_row(c, "random", "brakes", "collision")) == (8, 3, 1, 2, 2)
    assert _counts(_row(c, "inactive", "brakes", "timeout")) == (8, 1, 1, 1, 5)
    assert _counts(_row(c, "inactive", "brakes", "avoidable collision")) == (5, 2, 0, 2, 1)
    r = _row(c, "random", "brakes", "collision")
    assert r.a_only_episodes == [1] and r.b_only_episodes == [0]  # show=1: the first of each (of 1 and of 0, 5)
    assert "A only" in c.to_markdown(show=1) and "| 1 | 0 (+1) |" in c.to_markdown(show=1)


def test_the_floor_is_every_episode_no_agent_reached_the_goal_in(run):
    c = compare_runs([run], AGENTS, resamples=20)
    # no goal under any agent: 1 (C C T), 3 (T T T), 4 (C C C), 6 (C T C)
    assert list(c.floor.episode) == [1, 3, 4, 6]
    assert list(c.floor.doomed) == [True, False, True, False]
    assert list(c.floor["outcome:brakes"]) == ["timeout", "timeout", "collision", "collision"]
    con = sqlite3.connect(run / "results.db")
    seeds = dict(con.execute("SELECT episode, seed FROM episodes WHERE agent = 'random'").fetchall())
    con.close()
    assert list(c.floor.seed) == [seeds[e] for e in (1, 3, 4, 6)]
    line = (
        "Floor: 4 episodes that every one of random, inactive, brakes failed (no goal), 1 where every one "
        "collided, 2 of them from doomed starts; first: 1,3,4,6"
    )
    assert line in c.to_markdown()
    # two agents: random and brakes both fail in 1 2 3 4 6 (0 5 7 have a goal), both collide in 2 4 6
    two = compare_runs([run], ["random", "brakes"], resamples=20)
    assert list(two.floor.episode) == [1, 2, 3, 4, 6]
    assert (
        "5 episodes that every one of random, brakes failed (no goal), 3 where every one collided" in two.to_markdown()
    )


def _only(run: Path, dest: Path, agent: str, starts: bool = True, episodes=range(8)) -> Path:
    """A copy of the run's database holding ``agent``'s episodes ``episodes`` alone (and its starts'
    doomed flags, or none)."""
    dest.mkdir()
    shutil.copyfile(run / "results.db", dest / "results.db")
    keep = ",".join(map(str, episodes))
    statements = [
        ("DELETE FROM runs WHERE agent != ?", (agent,)),
        (f"DELETE FROM episodes WHERE agent != ? OR episode NOT IN ({keep})", (agent,)),
    ]
    if not starts:
        statements.append(("DELETE FROM starts",))
    _sql(dest / "results.db", *statements)
    return dest


def test_the_doomed_flags_come_from_whichever_run_has_them(run, tmp_path):
    """random's database has no starts, inactive's has: each way round, the avoidable rows and the
    floor read inactive's flags; neither has them: no avoidable row, a note says why."""
    a = _only(run, tmp_path / "a", "random", starts=False)
    b = _only(run, tmp_path / "b", "inactive")
    for dirs, names in (([a, b], ["random", "inactive"]), ([b, a], ["inactive", "random"])):
        c = compare_runs(dirs, names, resamples=20)
        r = _row(c, names[0], names[1], "avoidable collision")
        assert r.n == 5 and {*r.a_only_episodes, *r.b_only_episodes} == {0, 2, 5, 6}
        # random and inactive both fail in 1 3 4 6 7
        assert list(c.floor.episode) == [1, 3, 4, 6, 7]
        assert list(c.floor.doomed) == [True, False, True, False, True]
        assert not [n for n in c.notes if "not assessed" in n]
    bare = _only(run, tmp_path / "bare", "inactive", starts=False)
    c = compare_runs([a, bare], ["random", "inactive"], resamples=20)
    assert "avoidable collision" not in set(c.pairs.outcome)
    assert [n for n in c.notes if "starts not assessed for doomed" in n]
    assert list(c.floor.doomed) == [None] * 5
    assert "of them from doomed starts" not in c.to_markdown()


def test_shards_of_one_run_join_and_a_disagreeing_copy_is_refused(run, tmp_path):
    first = _only(run, tmp_path / "first", "random", episodes=range(4))
    second = _only(run, tmp_path / "second", "random", episodes=range(3, 8))  # episode 3 in both
    other = _only(run, tmp_path / "other", "inactive")
    joined = compare_runs([first, second, other], ["random", "inactive"], resamples=20)
    whole = compare_runs([run], ["random", "inactive"], resamples=20)
    cols = ["outcome", "n", "both", "a_only", "b_only", "neither"]
    assert joined.pairs[cols].equals(whole.pairs[cols])
    _sql(second / "results.db", ("UPDATE episodes SET outcome = 'goal' WHERE episode = 3",))
    with pytest.raises(ValueError) as e:
        compare_runs([first, second, other], ["random", "inactive"], resamples=20)
    assert str(e.value) == (
        f"random episode 3 is stored with outcome timeout in {first / 'results.db'} and goal in "
        f"{second / 'results.db'}: merge them first (rmm-bench merge) or compare one of them"
    )


def test_episodes_that_started_differently_are_not_paired(run, tmp_path):
    a = _only(run, tmp_path / "a", "random")
    b = _only(run, tmp_path / "b", "inactive")
    _sql(b / "results.db", ("UPDATE episodes SET start = 'ffffffffffffffff' WHERE episode = 5",))
    con = sqlite3.connect(a / "results.db")
    (fa,) = con.execute("SELECT start FROM episodes WHERE episode = 5").fetchone()
    con.close()
    with pytest.raises(ValueError) as e:
        compare_runs([a, b], ["random", "inactive"], resamples=20)
    assert str(e.value) == (
        f"random and inactive (Dubins4DParallel-v0 seed 0 clock fixed:1): episode 5 started differently (start "
        f"fingerprint {fa} in {a / 'results.db'}, ffffffffffffffff in {b / 'results.db'}): the runs come from "
        "code that shapes starts differently; compare them with --unpaired"
    )
    # a start stored before fingerprints: in one database it pairs, across two it cannot be checked
    _sql(b / "results.db", ("UPDATE episodes SET start = NULL WHERE episode = 5",))
    with pytest.raises(ValueError) as e:
        compare_runs([a, b], ["random", "inactive"], resamples=20)
    assert str(e.value) == (
        f"random and inactive (Dubins4DParallel-v0 seed 0 clock fixed:1): episode 5 has no start fingerprint in "
        f"{b / 'results.db'} (stored before results-store schema 3), so its start cannot be checked against the "
        "other database's; compare them with --unpaired"
    )
    _sql(b / "results.db", ("UPDATE episodes SET start = ? WHERE episode = 5", (fa,)))
    _sql(a / "results.db", ("UPDATE episodes SET start = NULL WHERE episode = 5",))
    with pytest.raises(ValueError, match=f"has no start fingerprint in {a / 'results.db'} "):
        compare_runs([a, b], ["random", "inactive"], resamples=20)
    both = tmp_path / "both"
    shutil.copytree(run, both)
    _sql(both / "results.db", ("UPDATE episodes SET start = NULL WHERE episode = 5",))
    c = compare_runs([both], ["random", "inactive"], resamples=20)
    assert _row(c, "random", "inactive", "goal").n == 8


def test_every_start_doomed_leaves_no_avoidable_episode(run, tmp_path):
    copy = tmp_path / "doomed"
    shutil.copytree(run, copy)
    _sql(copy / "results.db", ("UPDATE starts SET doomed = 1",))
    c = compare_runs([copy], ["random", "inactive"], resamples=20)
    r = _row(c, "random", "inactive", "avoidable collision")
    assert _counts(r) == (0, 0, 0, 0, 0) and math.isnan(r.rate_a) and math.isnan(r.rate_b) and math.isnan(r.diff)
    assert r.p_value == 1.0 and r.a_only_episodes == [] and r.b_only_episodes == []
    assert set(c.pairs["note"]) == {""}  # no errors: no note on any row


def test_an_empty_floor_keeps_its_columns(run, tmp_path):
    copy = tmp_path / "goal"
    shutil.copytree(run, copy)
    _sql(copy / "results.db", ("UPDATE episodes SET outcome = 'goal' WHERE agent = 'inactive'",))
    c = compare_runs([copy], ["random", "inactive"], resamples=20)
    assert len(c.floor) == 0
    assert list(c.floor.columns) == ["group", "episode", "seed", "doomed", "outcome:random", "outcome:inactive"]
    assert "Floor: no episode that every one of random, inactive failed." in c.to_markdown()


@pytest.fixture(scope="module")
def seed1(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("pairing") / "seed1"
    argv = ["--agent", "random,inactive", "--episodes", "4", "--clock", "fixed:1", "--seed", "1", "--workers", "1"]
    assert main([*argv, "--no-progress", "--no-figure", "--out", str(out)]) == 0
    return out


def test_runs_of_two_seeds_are_paired_within_each(run, seed1):
    """The same agents over seed 0 (8 episodes) and seed 1 (4): two groups, each counted on its own
    episodes (episode 0 of seed 0 is not episode 0 of seed 1)."""
    both = compare_runs([run, seed1], ["random", "inactive"], resamples=20)
    groups = {g: rows for g, rows in both.pairs.groupby("group")}
    assert set(groups) == {"Dubins4DParallel-v0 seed 0 clock fixed:1", "Dubins4DParallel-v0 seed 1 clock fixed:1"}
    alone = {s: compare_runs([d], ["random", "inactive"], resamples=20) for s, d in ((0, run), (1, seed1))}
    cols = ["outcome", "n", "both", "a_only", "b_only", "neither"]
    for s in (0, 1):
        mine = groups[f"Dubins4DParallel-v0 seed {s} clock fixed:1"][cols].reset_index(drop=True)
        assert mine.equals(alone[s].pairs[cols].reset_index(drop=True))
    assert set(both.floor.group) <= set(groups) and len(both.floor) == len(alone[0].floor) + len(alone[1].floor)
