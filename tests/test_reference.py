"""The reference results shipped in ``rmm_bench/reference``: portable, current, and still the same
bits as today's code (a change that moves a shipped episode fails here: regenerate them, see
docs/comparing.md)."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.compare import compare_runs
from rmm_bench.config import PROJECT_PACKAGES, run_key
from rmm_bench.reference import reference_dbs
from rmm_bench.store import SCHEMA_VERSION, ResultsStore

SHIPPED = {db.stem: db for db in reference_dbs()}
#: guardians whose episodes solve a value function first (seconds each): replayed in the slow tier
SOLVING = ("hj", "hj-paper")


def test_every_system_ships_its_fixed_clock_table():
    assert set(SHIPPED) == {"dubins4d", "maze", "quadrotor"}
    agents = {name: set() for name in SHIPPED}
    for name, db in SHIPPED.items():
        with sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True) as con:
            agents[name] = {a for (a,) in con.execute("SELECT agent FROM runs")}
            assert con.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
            # not WAL: a reader of a WAL file creates a -shm file beside it, which an installed
            # package's folder may not allow
            assert con.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
            for key, config in con.execute("SELECT run_key, config FROM runs"):
                config = json.loads(config)
                assert run_key(config) == key  # replay checks this
                assert config["env_kwargs"]["clock"] == "fixed:1"
                for path in config.get("inputs", {}):  # no path of the machine that made it
                    assert path.split("/")[0] in PROJECT_PACKAGES, path
    baselines = {"inactive", "random", "brakes", "lrmm", "cbf", "hj"}
    assert baselines | {"lrmm-paper", "cbf-paper", "hj-paper"} == agents["dubins4d"]
    assert baselines <= agents["maze"] and baselines <= agents["quadrotor"]


def _episodes_to_replay(db: Path, agent: str) -> list[int]:
    """The first episode of each outcome the agent had: the moments that move when code changes."""
    with sqlite3.connect(f"{db.resolve().as_uri()}?mode=ro", uri=True) as con:
        rows = con.execute(
            "SELECT MIN(episode) FROM episodes WHERE agent = ? GROUP BY outcome ORDER BY 1", (agent,)
        ).fetchall()
    return [int(e) for (e,) in rows]


def _cases(solving: bool):
    out = []
    for name, db in sorted(SHIPPED.items()):
        store = ResultsStore(db, read_only=True)
        try:
            agents = sorted({a for (a,) in store.db.execute("SELECT agent FROM runs")})
        finally:
            store.close()
        out += [(name, a) for a in agents if (a in SOLVING) == solving]
    return out


def _replay(tmp_path, name, agent, capsys):
    folder = tmp_path / name
    folder.mkdir()
    shutil.copy(SHIPPED[name], folder / "results.db")
    episodes = _episodes_to_replay(SHIPPED[name], agent)
    code = main(["replay", str(folder), "--agent", agent, "--episode", ",".join(map(str, episodes))])
    out = capsys.readouterr().out
    assert code == 0, out
    assert out.count("verified") >= len(episodes)


@pytest.mark.heavy
@pytest.mark.parametrize(("name", "agent"), _cases(solving=False))
def test_shipped_episodes_replay_to_the_same_bits(tmp_path, capsys, name, agent):
    _replay(tmp_path, name, agent, capsys)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "agent"), _cases(solving=True))
def test_shipped_episodes_of_the_solving_guardians_replay_to_the_same_bits(tmp_path, capsys, name, agent):
    _replay(tmp_path, name, agent, capsys)


def test_a_new_run_pairs_with_the_shipped_results(tmp_path):
    out = tmp_path / "mine"
    argv = ["--agent", "lrmm", "--episodes", "24", "--clock", "fixed:1", "--workers", "1", "--no-progress"]
    assert main([*argv, "--no-figure", "--out", str(out)]) == 0
    c = compare_runs([out], ["lrmm"], reference=True, resamples=10)
    assert {"ref:lrmm", "ref:cbf", "ref:hj", "ref:inactive"} <= set(c.agents)
    same = c.pairs[(c.pairs.a == "lrmm") & (c.pairs.b == "ref:lrmm")]
    assert list(same.outcome) == ["goal", "collision", "timeout", "avoidable collision"]
    assert (same.n[:3] == 24).all() and 0 < same.n.iloc[3] <= 24
    assert (same.a_only == 0).all() and (same.b_only == 0).all()  # today's lrmm is the shipped lrmm
