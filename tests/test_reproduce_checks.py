"""``rmm-bench reproduce``'s comparisons with the reruns stood in for: a table manifest's rows and
columns each checked against their own command's run (exactly under a fixed clock, by a
Bonferroni interval under the wall clock), failed and reused folders reported, and the quick
fingerprints compared agent by agent (tests/test_reproduce.py checks the manifests and the
shipped results; the slow tier reruns the quick versions)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from scipy.stats import norm

from rmm_bench import reproduce
from rmm_bench.manifest import load_manifests
from rmm_bench.paired import newcombe_unpaired

REFERENCE = Path(__file__).resolve().parents[1] / "benchmarks" / "bench" / "reference"
EPISODES = 256


def _published(m, k: int) -> dict[str, dict[str, tuple[float, int]]]:
    """Row ``k``'s published rates of a table manifest, as :func:`reproduce._rates` returns a run's."""
    out: dict[str, dict[str, tuple[float, int]]] = {}
    for e in reproduce.expected_rates(m, {k}):
        out.setdefault(e["agent"], {})[e["column"]] = (e["value"], EPISODES)
    return out


@pytest.fixture
def reruns(monkeypatch):
    """``_run`` records its commands and folder and creates the folder; ``_rates`` answers for each
    folder from ``rates[folder name]`` (set by the test)."""
    calls: list[tuple[list, str]] = []
    rates: dict[str, dict] = {}

    def run(commands, out):
        calls.append((commands, out.name))
        out.mkdir(parents=True, exist_ok=True)
        (out / "results.db").write_bytes(b"")
        if out.name in rates.get("fail", ()):
            raise RuntimeError(f"rmm-bench {' '.join(commands[0])} exited with 1")

    monkeypatch.setattr(reproduce, "_run", run)
    monkeypatch.setattr(reproduce, "_rates", lambda db: rates[db.parent.name])
    return calls, rates


def test_each_row_of_a_sweep_is_checked_against_its_own_run(tmp_path, reruns):
    calls, rates = reruns
    m = load_manifests(["knob-lrmm-threshold"])[0]
    for k in range(8):
        rates[f"row-{k + 1}"] = _published(m, k)
    assert reproduce.check_full(m, tmp_path / "a") == []
    assert [name for _, name in calls] == [f"row-{k + 1}" for k in range(8)]
    assert calls[2][0] == [
        [
            "--agent",
            "lrmm",
            "--agent-opt",
            "lrmm.threshold=0.25",
            "--episodes",
            "256",
            "--seed",
            "0",
            "--clock",
            "fixed:1",
        ]
    ]
    # the default's row measured 0.2 points off in collisions: exactly that cell fails (a fixed clock)
    rates["row-3"]["lrmm"]["collision"] = (9.2, EPISODES)
    assert reproduce.check_full(m, tmp_path / "b") == [
        "knob-lrmm-threshold: lrmm collision 9.2% over 256 episodes under the fixed clock; the published 9.0% "
        "differs (a fixed-clock rerun gives the same episodes)"
    ]


def _wall(m) -> None:
    m.check["commands"] = [c.replace("--clock fixed:1", "--clock wall") for c in m.check["commands"]]


def test_a_wall_clock_sweep_is_checked_by_a_bonferroni_interval(tmp_path, reruns):
    """Under the wall clock a rerun is another sample: row 8's goal rate may move as far as the
    95% interval Bonferroni-corrected over the manifest's 24 cells allows, not further."""
    calls, rates = reruns
    m = load_manifests(["knob-lrmm-threshold"])[0]
    _wall(m)
    for k in range(8):
        rates[f"row-{k + 1}"] = _published(m, k)
    cells = len(reproduce.expected_rates(m))
    assert cells == 24
    z1, z24 = float(norm.ppf(1 - 0.025)), float(norm.ppf(1 - 0.025 / 24))
    published = 45.3  # inactive's goal rate
    x = round(published / 100 * EPISODES)

    def inside(got: int, z: float) -> bool:
        _, lo, hi = newcombe_unpaired(got, EPISODES, x, EPISODES, z)
        return lo <= 0 <= hi

    # a measured count outside the plain 95% interval but inside the corrected one
    got = next(g for g in range(x, EPISODES) if not inside(g, z1))
    assert inside(got, z24)
    rates["row-8"]["inactive"]["goal"] = (100 * got / EPISODES, EPISODES)
    assert reproduce.check_full(m, tmp_path / "a") == []
    beyond = next(g for g in range(x, EPISODES) if not inside(g, z24))
    rates["row-8"]["inactive"]["goal"] = (100 * beyond / EPISODES, EPISODES)
    d, lo, hi = newcombe_unpaired(beyond, EPISODES, x, EPISODES, z24)
    assert reproduce.check_full(m, tmp_path / "b") == [
        f"knob-lrmm-threshold: inactive goal {100 * beyond / EPISODES:.1f}% over 256 episodes; the published 45.3% "
        f"differs by {100 * d:+.1f} points, outside the interval [{100 * lo:.1f}, {100 * hi:.1f}] (95%, Bonferroni "
        "over 24 rates)"
    ]


def test_each_column_of_a_table_is_checked_against_its_own_run(tmp_path, reruns):
    calls, rates = reruns
    m = load_manifests(["latency-sweep"])[0]
    columns = list(m.check["columns"])
    for k, col in enumerate(columns):
        got: dict[str, dict] = {}
        for e in reproduce.expected_rates(m, columns={col}):
            got.setdefault(e["agent"], {})[e["column"]] = (e["value"], EPISODES)
        rates[f"column-{k + 1}"] = got
    assert reproduce.check_full(m, tmp_path / "a") == []
    assert [name for _, name in calls] == [f"column-{k + 1}" for k in range(len(columns))]
    assert calls[2][0] == [["--agent", "lrmm,cbf", "--clock", "fixed:20", "--episodes", "256", "--seed", "0"]]
    rates["column-3"]["cbf"]["collision"] = (7.4, EPISODES)
    assert reproduce.check_full(m, tmp_path / "b") == [
        "latency-sweep: cbf collision 7.4% over 256 episodes under the fixed clock; the published 7.0% differs "
        "(a fixed-clock rerun gives the same episodes)"
    ]


def test_a_failed_run_and_a_used_folder_are_reported_and_the_rest_checked(tmp_path, reruns):
    calls, rates = reruns
    m = load_manifests(["knob-lrmm-threshold"])[0]
    for k in range(8):
        rates[f"row-{k + 1}"] = _published(m, k)
    rates["fail"] = {"row-2"}
    (tmp_path / "row-5").mkdir(parents=True)
    (tmp_path / "row-5" / "results.db").write_bytes(b"")
    rates["row-7"]["lrmm"]["goal"] = (61.0, EPISODES)
    assert reproduce.check_full(m, tmp_path) == [
        "knob-lrmm-threshold: rmm-bench --agent lrmm --agent-opt lrmm.threshold=0.2 --episodes 256 --seed 0 --clock "
        "fixed:1 exited with 1",
        f"knob-lrmm-threshold: {tmp_path / 'row-5'} already holds results; a full check reruns: give an empty --out",
        "knob-lrmm-threshold: lrmm goal 61.0% over 256 episodes under the fixed clock; the published 60.5% differs "
        "(a fixed-clock rerun gives the same episodes)",
    ]
    assert [name for _, name in calls] == ["row-1", "row-2", "row-3", "row-4", "row-6", "row-7", "row-8"]


def test_a_reference_manifests_commands_run_once_into_the_folder(tmp_path, reruns):
    calls, rates = reruns
    m = load_manifests(["maze-fixed"])[0]
    measured: dict[str, dict] = {}
    for e in m.expect:
        measured.setdefault(e["agent"], {})[e["column"]] = (e["value"], EPISODES)
    rates["a"] = measured
    assert reproduce.check_full(m, tmp_path / "a") == []
    assert calls == [(m.commands, "a")]
    # an agent the rerun did not run: each of its published rates is reported unmeasured
    rates["b"] = {a: r for a, r in measured.items() if a != "hj"}
    assert reproduce.check_full(m, tmp_path / "b") == [
        f"maze-fixed: hj: no {column} rate measured" for column in ("goal", "collision", "timeout")
    ]


# ---------------------------------------------------------------- the quick fingerprints


def test_quick_fingerprints_are_compared_agent_by_agent(tmp_path, monkeypatch):
    m = load_manifests(["maze-fixed"])[0]
    out = tmp_path / "out"
    out.mkdir()
    shutil.copyfile(REFERENCE / "maze.db", out / "results.db")
    got = dict(m.fingerprints)

    def quick(m_, o):
        assert m_ is m and o == out
        return got

    monkeypatch.setattr(reproduce, "_quick_fingerprints", quick)
    assert reproduce.check_quick(m, out) == []
    got["cbf"] = "0000000000000000"
    del got["random"]
    got["dataset"] = "1111111111111111"
    assert reproduce.check_quick(m, out) == [
        f"maze-fixed: cbf: fingerprint 0000000000000000 (expected {m.fingerprints['cbf']}), 256 episodes; replay one "
        "with rmm-bench replay DIR --agent cbf --episode 0",
        f"maze-fixed: dataset: fingerprint 1111111111111111 (expected None), the dataset in {out / 'data'}",
        f"maze-fixed: random: fingerprint None (expected {m.fingerprints['random']}), 256 episodes; replay one with "
        "rmm-bench replay DIR --agent random --episode 0",
    ]
    assert all(re.fullmatch(r"[0-9a-f]{16}", v) for v in m.fingerprints.values())


def test_a_fixed_clock_rate_within_half_a_point_reproduces(tmp_path, reruns):
    """The published figures have one decimal: a rerun's rate within 0.05 points of one is it."""
    calls, rates = reruns
    m = load_manifests(["knob-lrmm-threshold"])[0]
    for k in range(8):
        rates[f"row-{k + 1}"] = _published(m, k)
    rates["row-3"]["lrmm"]["collision"] = (9.05, EPISODES)
    assert reproduce.check_full(m, tmp_path / "a") == []
    rates["row-3"]["lrmm"]["collision"] = (9.06, EPISODES)
    assert len(reproduce.check_full(m, tmp_path / "b")) == 1


def test_one_wall_clock_rate_is_checked_by_the_plain_95_percent_interval(tmp_path, reruns):
    """One cell (the default): no Bonferroni correction; the message gives the interval."""
    calls, rates = reruns
    m = load_manifests(["maze-fixed"])[0]
    m.expect = [{"agent": "inactive", "column": "collision", "value": 46.1}]
    x = round(46.1 / 100 * EPISODES)

    def inside(got: int, z: float) -> bool:
        _, lo, hi = newcombe_unpaired(got, EPISODES, x, EPISODES, z)
        return lo <= 0 <= hi

    z95, z975 = float(norm.ppf(1 - 0.025)), float(norm.ppf(1 - 0.0125))
    got = next(g for g in range(x, EPISODES) if not inside(g, z95))
    assert inside(got, z975)  # a wider interval (two cells) would take it
    rates["r"] = {"inactive": {"collision": (100 * got / EPISODES, EPISODES)}}
    (tmp_path / "r").mkdir()
    d, lo, hi = newcombe_unpaired(got, EPISODES, x, EPISODES, z95)
    assert reproduce._check_rates(m, tmp_path / "r" / "results.db", exact=False) == [
        f"maze-fixed: inactive collision {100 * got / EPISODES:.1f}% over 256 episodes; the published 46.1% differs by "
        f"{100 * d:+.1f} points, outside the interval [{100 * lo:.1f}, {100 * hi:.1f}] (95%, Bonferroni over 1 rates)"
    ]
    # far off: 118 of 256 measured (46.1%), 30.0% published (77 of 256): the interval 7.6 to 24.1 points
    m.expect = [{"agent": "inactive", "column": "collision", "value": 30.0}]
    rates["r"] = {"inactive": {"collision": (100 * 118 / EPISODES, EPISODES)}}
    assert reproduce._check_rates(m, tmp_path / "r" / "results.db", exact=False) == [
        "maze-fixed: inactive collision 46.1% over 256 episodes; the published 30.0% differs by +16.0 points, outside "
        "the interval [7.6, 24.1] (95%, Bonferroni over 1 rates)"
    ]


def test_a_table_without_a_check_reruns_nothing_and_its_ratios_share_one_run(tmp_path, reruns, monkeypatch):
    calls, rates = reruns
    seen = []
    monkeypatch.setattr(reproduce, "check_ratio", lambda m, r, outputs: seen.append((m, r, outputs)) or [])
    m = load_manifests(["performance"])[0]
    assert m.kind == "table" and not m.check and len(m.ratios) == 4
    assert reproduce.expected_rates(m) == []
    assert reproduce.check_full(m, tmp_path) == [] and calls == []
    assert [r for _, r, _ in seen] == m.ratios and all(x is m for x, _, _ in seen)
    assert len({id(o) for _, _, o in seen}) == 1 and isinstance(seen[0][2], dict)
    plain = load_manifests(["paired-2048"])[0]
    assert plain.kind == "table" and not plain.check and plain.commands and not plain.ratios
    assert reproduce.expected_rates(plain) == [] and reproduce.check_full(plain, tmp_path / "p") == [] and calls == []


def test_rows_of_a_table_that_are_not_ours_are_not_expected():
    """dubins4d-wall's paper rows have the agent '' in [check]: no rate of theirs is expected."""
    m = load_manifests(["dubins4d-wall"])[0]
    ours = [a for a in m.check["agents"] if a]
    got = reproduce.expected_rates(m)
    assert len(ours) < len(m.check["agents"]) and len(got) == 3 * len(ours)
    assert [e["agent"] for e in got[::3]] == ours


def test_the_rates_of_a_run_count_its_episodes_with_a_result_and_never_write_it(tmp_path):
    import hashlib

    db = tmp_path / "maze.db"
    shutil.copyfile(REFERENCE / "maze.db", db)
    import sqlite3

    con = sqlite3.connect(db)
    con.execute(
        "UPDATE episodes SET outcome = 'error', error_kind = 'guardian' WHERE agent = 'inactive' AND episode < 3"
    )
    con.commit()
    con.close()
    before = hashlib.sha256(db.read_bytes()).hexdigest()
    rates = reproduce._rates(db)
    assert hashlib.sha256(db.read_bytes()).hexdigest() == before
    assert {c: n for c, (_, n) in rates["inactive"].items()} == {"goal": 253, "collision": 253, "timeout": 253}
    assert {c: n for c, (_, n) in rates["cbf"].items()} == {"goal": 256, "collision": 256, "timeout": 256}


def test_a_fingerprint_reads_no_statistics_as_none(tmp_path):
    """A row stored with no guardian statistics (NULL) and one with an empty set ('{}') are the same
    episode: the same fingerprint."""
    import sqlite3

    db = tmp_path / "maze.db"
    shutil.copyfile(REFERENCE / "maze.db", db)
    con = sqlite3.connect(db)
    con.execute("UPDATE episodes SET guardian_stats = '{}' WHERE agent = 'inactive'")
    con.commit()
    empty = reproduce.fingerprint(db, 4)
    con.execute("UPDATE episodes SET guardian_stats = NULL WHERE agent = 'inactive'")
    con.commit()
    con.close()
    assert reproduce.fingerprint(db, 4) == empty
