"""Fault drills of issue 25 ("nothing silently wrong"): a run is keyed on the bytes of the files
it reads, storage errors are told apart and never advise throwing data away, the HJ cache is
verified, guardian errors count in the rates and fail the command, a merged report keeps its
configurations apart, and huge or deep input is refused before it is used.

Each drill repeats a finding of the issue as a user would meet it, with a tiny run (a few
episodes of cheap guardians)."""

import json
import os
import shutil
import sqlite3

import pytest

from rmm_bench.cli import main
from tests.bench_helpers import query

# tables and the database only: the figure has its own tests (test_bench, test_cli_figures)
FAST = ["--clock", "fixed:1", "--no-progress", "--workers", "1", "--no-figure"]


def stored(out, cols="run_key, agent, episode, outcome, error_kind"):
    return query(out, f"SELECT {cols} FROM episodes ORDER BY run_key, episode")


# ------------------------------------------------------------------ 1. a run is what ran
def _two_models(tmp_path):
    """The shipped Dubins4D head model, and the same weights with other metadata (other bytes)."""
    from rmm_guardians.lrmm.model import LRMMModel, default_model_path

    first = tmp_path / "first.npz"
    second = tmp_path / "second.npz"
    shutil.copy(default_model_path("Dubins4DParallel-v0", variant="act"), first)
    model = LRMMModel.load(first)
    model.meta["note"] = "a drill: a different model file"
    model.save(second)
    assert first.read_bytes() != second.read_bytes()
    return first, second


#: the shipped decision given as arguments: the runs below read the model file only
DECISION = {"threshold": 0.25, "strategies": "SafestCandidate, Commit(steps=18), Restart(speed=0.3)"}
DECISION_OPTS = [
    "--agent-opt",
    "lrmm.threshold=0.25",
    "--agent-opt",
    f"lrmm.strategies={json.dumps(DECISION['strategies'])}",
]


def test_resume_after_the_model_file_changed_starts_a_new_run_naming_the_file(tmp_path, capsys):
    first, second = _two_models(tmp_path)
    model = tmp_path / "model.npz"
    shutil.copy(first, model)
    out = tmp_path / "r"
    cmd = [
        "--agent",
        "lrmm",
        "--agent-opt",
        f"lrmm.model={model}",
        *DECISION_OPTS,
        "--out",
        str(out),
        "--env",
        "Dubins4DParallel-v0",
        *FAST,
    ]
    assert main(cmd + ["--episodes", "2"]) == 0
    (old_key,) = {r[0] for r in stored(out)}
    capsys.readouterr()

    shutil.copy(second, model)  # the same path, other bytes
    assert main(cmd + ["--episodes", "4", "--resume"]) == 0
    err = capsys.readouterr().err
    assert f"lrmm: 2 episodes in {out / 'results.db'} were run with other files: {model}" in err
    assert "this command starts a new run" in err and f"the old episodes stay under run {old_key}" in err
    runs = {}
    for key, _, episode, _, _ in stored(out):
        runs.setdefault(key, []).append(episode)
    assert runs.pop(old_key) == [0, 1]  # untouched
    ((new_key, episodes),) = runs.items()
    assert episodes == [0, 1, 2, 3]  # every episode of the new run ran with the new file
    con = sqlite3.connect(out / "results.db")
    inputs = {k: json.loads(c)["inputs"] for k, c in con.execute("SELECT run_key, config FROM runs")}
    con.close()
    from rmm_bench.config import file_sha256

    assert inputs == {old_key: {str(model): file_sha256(first)}, new_key: {str(model): file_sha256(second)}}

    # the same bytes again: the same run, nothing to do and nothing announced
    assert main(cmd + ["--episodes", "4", "--resume"]) == 0
    assert "other files" not in capsys.readouterr().err
    assert len(stored(out)) == 6


def test_shipped_model_is_part_of_the_run_key(tmp_path):
    from rmm_bench.config import AgentRun, file_sha256
    from rmm_bench.run_checks import check_runs
    from rmm_guardians.lrmm.model import default_model_path

    run = AgentRun("lrmm", {}, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 60.0, False)
    meta = check_runs({"lrmm": run})
    shipped = default_model_path("Dubins4DParallel-v0", variant="act")
    # named by its place in the package: the same key on every machine and checkout
    name = "rmm_guardians/lrmm/models/dubins4d_act.npz"
    assert meta["lrmm"]["inputs"] == {name: file_sha256(shipped)}
    keyed = AgentRun(**{**run.__dict__, "inputs": meta["lrmm"]["inputs"]})
    other = AgentRun(**{**run.__dict__, "inputs": {name: "0" * 64}})
    assert len({run.key, keyed.key, other.key}) == 3
    inactive = AgentRun("inactive", {}, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 60.0, False)
    assert check_runs({"inactive": inactive})["inactive"]["inputs"] == {}
    assert "inputs" not in inactive.as_dict()  # runs that read no file keep the keys they always had


def test_a_file_changed_while_the_run_runs_is_not_used(tmp_path):
    from rmm_bench.config import AgentRun, EpisodeTask, file_sha256
    from rmm_bench.runner import run_episode
    from rmm_bench.store import RETRIED_ERRORS

    first, second = _two_models(tmp_path)
    run = AgentRun(
        "lrmm",
        {"model": str(second), **DECISION},
        "Dubins4DParallel-v0",
        {"clock": "fixed:1"},
        0,
        60.0,
        False,
        inputs={str(second): file_sha256(first)},
    )  # keyed before the file was replaced
    res = run_episode(EpisodeTask(run=run, run_key=run.key, episode=0, seed=1))
    assert res.outcome == "error" and res.error_kind == "input_changed" and "input_changed" in RETRIED_ERRORS
    assert (
        f"{second} (sha256 {file_sha256(first)[:12]}... when the run was keyed, {file_sha256(second)[:12]}... now)"
        in res.error
    )


# ------------------------------------------------------------------ 4. honest rates
from rmm_guardians.base import Guardian  # noqa: E402


class ErrsOnEvenSeeds(Guardian):
    """Lets the driver drive, but raises in its first decision of every episode with an even seed
    (a guardian that fails exactly when it would matter)."""

    name = "errs-on-even-seeds"
    observation_type = "none"

    def reset(self, **kw):
        super().reset(**kw)
        self.seed = kw.get("seed")

    def act(self, obs, info):
        if self.seed % 2 == 0:
            raise ValueError("turnrate_ctrl must be finite, got inf")
        return self.action_space.inactive()


def test_guardian_errors_count_as_failures_and_the_command_fails_naming_them(tmp_path, capsys):
    from rmm_bench.runner import episode_seed

    n, agent = 8, "tests.test_faults_honest:ErrsOnEvenSeeds"
    out = tmp_path / "r"
    assert (
        main(
            [
                "--agent",
                f"{agent},inactive",
                "--episodes",
                str(n),
                "--out",
                str(out),
                "--batch-size",
                str(n),
                "--env",
                "Dubins4DParallel-v0",
                *FAST,
            ]
        )
        == 1
    )
    captured = capsys.readouterr()
    got = {(a, e): o for _, a, e, o, _ in stored(out)}
    even = [i for i in range(n) if episode_seed(0, i) % 2 == 0]
    assert 0 < len(even) < n and [e for e in range(n) if got[(agent, e)] == "error"] == even
    # where it did not err, it never acted: the same outcome as the inactive agent's
    goals = sum(got[("inactive", e)] == "goal" for e in range(n) if e not in even)
    collisions = sum(got[("inactive", e)] == "collision" for e in range(n) if e not in even)
    cells = [c.strip() for c in captured.out.split(f"| {agent} |")[1].split("\n")[0].split("|")]
    from rmm_bench.metrics import wilson_interval

    def one_batch(k):  # one batch: the rate over all n, with its 95% Wilson interval
        lo, hi = wilson_interval(k / n, n)
        return f"{100 * k / n:.1f} [{100 * lo:.1f}, {100 * hi:.1f}]†"

    # cells: agent, obs, obstacles, episodes, compute, measured decision time (fixed clock), success, collision
    assert cells[5] == one_batch(goals) and cells[6] == one_batch(collisions)  # over all n
    assert cells[-3] == str(len(even))
    (line,) = [ln for ln in captured.err.splitlines() if agent in ln]
    assert line.startswith(
        f"rmm-bench: {agent}: {len(even)} of {n} episodes ended in a guardian error, counted as failures "
        f"in the rates (first, episode {even[0]}: ValueError: turnrate_ctrl must be finite, got inf)"
    )
    assert "--retry-errors" in line and not [
        ln for ln in captured.err.splitlines() if ln.startswith("rmm-bench: inactive")
    ]


# ------------------------------------------------------------------ 2 and 8. storage errors told apart, one line each
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_out_naming_a_file_is_bad_input_in_one_line(tmp_path, capsys):
    from rmm_envs.risk.datagen import main as datagen

    afile = tmp_path / "afile"
    afile.write_text("mine")
    assert main(["--agent", "inactive", "--episodes", "1", "--out", str(afile), *FAST]) == 2
    assert _one_line(capsys.readouterr().err) == (
        f"rmm-bench: error: {afile} is a file, not a directory (File exists); choose another --out"
    )
    assert main(["--agent", "inactive", "--episodes", "1", "--out", str(afile / "sub"), *FAST]) == 2
    assert "a part of this path is a file, not a directory" in _one_line(capsys.readouterr().err)
    assert (
        datagen(
            [
                "--configs",
                "2",
                "--samples-per-config",
                "2",
                "--branches",
                "2",
                "--depth",
                "1",
                "--out",
                str(afile),
                "--no-progress",
                "--workers",
                "1",
            ]
        )
        == 2
    )
    assert _one_line(capsys.readouterr().err) == (
        f"rmm-datagen: error: {afile} is a file, not a directory (File exists); choose another --out"
    )
    assert afile.read_text() == "mine"


def _bench(args, limit_bytes=None):
    """rmm-bench in a child process, under a file-size limit (``ulimit -f``) when given."""

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))

    return subprocess.run(
        [sys.executable, "-m", "rmm_bench.cli", *map(str, args)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=limit if limit_bytes else None,
    )


@pytest.mark.heavy
def test_file_size_limit_mid_run_is_a_run_failure_that_keeps_every_episode(tmp_path, capsys):
    # only the limited run needs a child process (the limit is the whole process's); the runs
    # before and after it are the same command in this one
    out = tmp_path / "r"
    cmd = ["--agent", "inactive", "--out", str(out), *FAST]
    assert main(cmd + ["--episodes", "2"]) == 0
    before = stored(out, "episode, outcome, steps")
    db = out / "results.db"
    # 40 episodes: the limit stops the run after a few (each episode is a row and an index entry)
    res = _bench(cmd + ["--episodes", "40"], limit_bytes=db.stat().st_size + 16384)
    assert res.returncode == 1, res.stderr
    line = _one_line(res.stderr)
    assert line.startswith(
        f"rmm-bench: error: cannot write {db} (disk I/O error): it reached the file-size limit (ulimit -f: "
    )
    assert line.endswith(
        "raise the limit (ulimit -f unlimited), then the stored episodes are kept: rerun the same command"
    )
    assert "move it aside" not in line and "damaged" not in line
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchall() == [("ok",)]
    con.close()
    kept = stored(out, "episode, outcome, steps")
    assert kept[:2] == before and len(kept) < 40  # stopped mid-run
    capsys.readouterr()
    assert main(cmd + ["--episodes", "40"]) == 0  # the same command, the limit lifted
    assert [r[0] for r in stored(out, "episode")] == list(range(40))


def test_disk_full_while_writing_the_tables_is_one_line_naming_the_directory(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["--agent", "inactive", "--episodes", "2", "--out", str(out), *FAST]) == 0
    (out / "table_I.md").unlink()
    (out / "table_I.md").symlink_to("/dev/full")  # every write there fails with ENOSPC
    capsys.readouterr()
    assert main(["report", str(out)]) == 1
    assert _one_line(capsys.readouterr().err) == (
        f"rmm-bench: error: no space left to write {out} (No space left on device); "
        "free disk space (or quota), then what is stored is kept: rerun the same command"
    )


def test_a_read_only_database_is_not_called_damaged(tmp_path, capsys):
    """Permissions cannot make a file read-only for root (tests may run as root); SQLite's own read-only mode
    gives the error it raises for a read-only file, directory or file system."""
    from rmm_bench.store import ResultsStore

    out = tmp_path / "r"
    assert main(["--agent", "inactive", "--episodes", "2", "--out", str(out), *FAST]) == 0
    db = out / "results.db"
    ro = sqlite3.connect(db.resolve().as_uri() + "?mode=ro", uri=True)
    with pytest.raises(sqlite3.OperationalError) as info:
        ro.execute("DELETE FROM episodes")
    ro.close()
    store = ResultsStore(db)
    try:
        err = store._error(info.value)
    finally:
        store.close()
    assert err.status == 2 and str(err).startswith(
        f"cannot write {db} (attempt to write a readonly database): the file, its directory"
    )
    assert "damaged" not in str(err) and "move it aside" not in str(err) and "the database is intact" in str(err)


def test_a_damaged_database_says_what_moving_it_aside_loses_and_how_to_export(tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    db = out / "results.db"
    db.write_bytes(b"this is not a database " * 200)
    assert main(["report", str(out)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert f"sqlite3 {db} .recover > {db}.sql" in line and f"mv {db} {db}.damaged" in line
    assert line.index(".recover") < line.index("mv ")  # export first
    assert "the episodes of the old one are lost to rmm-bench" in line


# ------------------------------------------------------------------ 3. a verified HJ value cache
def _hj_guardian(cache_dir):
    import numpy as np

    from rmm_envs.autonomy import GuardianActionSpace
    from rmm_envs.systems.dubins4d.dynamics import Dubins4D
    from rmm_envs.systems.dubins4d.env import CONTROLS
    from rmm_guardians.hj.grid import Grid
    from rmm_guardians.hj.guardian import HJGuardian

    grid = Grid([-8.0, -8.0, -np.pi, 0.0], [8.0, 8.0, np.pi, 2.0], [33, 33, 16, 9], periodic=[2])
    g = HJGuardian(grid=grid, horizon=2.0, cache_dir=cache_dir)
    space = GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, dynamics_name="dubins4d")
    box = {
        "obstacles": np.array([[0.0, 0.0, 2.0]]),
        "goal": np.array([7.0, 7.0, 0.5]),
        "state": np.array([-3.0, 0.0, 0.0, 2.0]),
    }
    return g, (lambda seed: g.reset(seed=seed, privileged=lambda: box, action_space=space))


def _safe_everywhere(entry, V):
    """The edit of the finding: the entry's array replaced by one of the same shape saying 'safe'."""
    import numpy as np

    with np.load(entry) as z:
        meta = z["meta"]
    np.savez(entry, V=np.full_like(V, 50.0), meta=meta)


def _raw_npy(entry, V):
    import numpy as np

    with open(entry, "wb") as fh:
        np.save(fh, np.full_like(V, 50.0))


def _other_solve(entry, V):
    """A genuine entry of another solve (another horizon) renamed to this one's name."""

    from rmm_guardians.hj.cache import ValueCache

    other = ValueCache(entry.parent / "other")
    other.save("x", V + 1.0, {"horizon": 9.0})
    os.replace(other.path("x"), entry)


@pytest.mark.parametrize(
    "edit, problem",
    [
        (_safe_everywhere, "does not match its recorded checksum"),
        (_raw_npy, "is not a verified entry"),
        (_other_solve, "was solved for other parameters"),
    ],
)
def test_an_edited_hj_cache_entry_is_recomputed_and_said_once(tmp_path, edit, problem):
    import warnings

    import numpy as np

    g, reset = _hj_guardian(tmp_path)
    reset(0)
    solved = g.V.copy()
    assert g.act(None, {})["active_ctrl"] == 1  # heading into the obstacle: it takes control
    (entry,) = tmp_path.glob("*.npz")
    edit(entry, solved)
    with pytest.warns(RuntimeWarning) as said:
        reset(1)
    assert [str(w.message) for w in said] == [
        f"HJ value cache entry {entry} {problem}" + str(said[0].message).split(problem)[1]
    ]
    assert str(said[0].message).endswith("; recomputing it")
    assert g.stats()["cache_rejected"] == 1 and g.stats()["solves"] == 1 and g.stats()["cache_hits"] == 0
    np.testing.assert_array_equal(g.V, solved)
    assert g.act(None, {})["active_ctrl"] == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the recomputed entry replaced the bad one: nothing more to say
        reset(2)
    assert g.stats()["cache_hits"] == 1 and g.stats()["solves"] == 0
    np.testing.assert_array_equal(g.V, solved)


# ------------------------------------------------------------------ 5. a merged report keeps its configurations apart
def test_a_report_over_two_configurations_prints_one_header_each(tmp_path, capsys):
    import csv

    out = tmp_path / "r"
    assert (
        main(
            [
                "--agent",
                "inactive",
                "--episodes",
                "1",
                "--seed",
                "1",
                "--out",
                str(out),
                "--env",
                "Dubins4DParallel-v0",
                *FAST,
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "--agent",
                "brakes",
                "--episodes",
                "1",
                "--seed",
                "2",
                "--out",
                str(out),
                "--env",
                "Dubins3DMazeParallel-v0",
                "--clock",
                "fixed:20",
                "--no-progress",
                "--workers",
                "1",
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["report", str(out), "--invocation", "1", "--invocation", "2"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("2 configurations, one table each (they differ in env, clock, seed):")
    first = "Table I [1]: Dubins4DParallel-v0, clock fixed:1, time accel 10.0, seed 1, 1 episodes requested per agent"
    second = (
        "Table I [2]: Dubins3DMazeParallel-v0, clock fixed:20, time accel 10.0, seed 2, 1 episodes requested per agent"
    )
    assert first in text and second in text
    a, b = text.index(first), text.index(second)
    assert a < text.index("| inactive |") < b < text.index("| brakes |")  # each row under its own header
    md = (out / "table_I.md").read_text()
    assert (
        md.index("[1] Dubins4DParallel-v0, clock fixed:1")
        < md.index("| inactive |")
        < md.index("[2] Dubins3DMazeParallel-v0, clock fixed:20")
        < md.index("| brakes |")
    )
    with open(out / "table_I.csv") as fh:
        got = [(r["agent"], r["env"], r["clock"], r["seed"]) for r in csv.DictReader(fh)]
    assert got == [
        ("inactive", "Dubins4DParallel-v0", "fixed:1", "1"),
        ("brakes", "Dubins3DMazeParallel-v0", "fixed:20", "2"),
    ]
    # one configuration: the table as it always was, no numbering
    assert main(["report", str(out), "--invocation", "2"]) == 0
    assert capsys.readouterr().out.startswith(
        "Table I: Dubins3DMazeParallel-v0, clock fixed:20, time accel 10.0, seed 2"
    )
    assert (out / "table_I.md").read_text().startswith("| Agent |")


# ------------------------------------------------------------------ 9. model files checked before they are used
def _edited_model(tmp_path, arrays=None, meta=None, drop=()):
    """The shipped Dubins4D head model with some arrays or metadata replaced, its checksum made
    consistent again (the edits a tool, not a damaged disk, would make)."""
    import numpy as np

    from rmm_guardians.lrmm.model import _checksum, default_model_path

    with np.load(default_model_path("Dubins4DParallel-v0", variant="act")) as z:
        arrs = {k: z[k] for k in z.files}
    m = json.loads(arrs.pop("meta").tobytes().decode())
    arrs.update(arrays or {})
    m.update(meta or {})
    for k in drop:
        m.pop(k)
    m["weights_sha256"] = _checksum(arrs)
    path = tmp_path / "edited.npz"
    np.savez(path, meta=np.frombuffer(json.dumps(m).encode(), dtype=np.uint8), **arrs)
    return path


def _W0():
    import numpy as np

    from rmm_guardians.lrmm.model import default_model_path

    with np.load(default_model_path("Dubins4DParallel-v0", variant="act")) as z:
        return z["W0"]


@pytest.mark.parametrize(
    "edit, message",
    [
        (
            dict(arrays={"W0": _W0() * (1 + 1j)}),
            "LRMM model array 'W0' has dtype complex128; expected real numbers (float)",
        ),
        (dict(meta={"candidate_hold": -5}), "meta 'candidate_hold' must be a finite number of seconds > 0, got -5"),
        (dict(meta={"candidate_hold": 1e999}), "meta 'candidate_hold' must be a finite number of seconds > 0, got inf"),
        (dict(drop=("hidden",)), "metadata lacks ['hidden']: not a complete LRMM model file"),
        (
            dict(meta={"candidates": [[1e308, 0.5]] * 6}),
            "candidate controls [[1e+308, 0.5], [1e+308, 0.5], [1e+308, 0.5], [1e+308, 0.5], [1e+308, 0.5], [1e+308, 0.5]] of ",
        ),
    ],
    ids=["complex", "negative-hold", "infinite-hold", "no-hidden", "huge-candidates"],
)
def test_a_bad_model_file_is_refused_before_any_episode_naming_the_value(tmp_path, capsys, edit, message):
    path = _edited_model(tmp_path, **edit)
    out = tmp_path / "r"
    assert (
        main(
            [
                "--agent",
                "lrmm",
                "--agent-opt",
                f"lrmm.model={path}",
                *DECISION_OPTS,
                "--episodes",
                "1",
                "--out",
                str(out),
                "--env",
                "Dubins4DParallel-v0",
                *FAST,
            ]
        )
        == 2
    )
    line = _one_line(capsys.readouterr().err)
    assert str(path) in line and message in line and "KeyError" not in line
    assert not out.exists()


# ------------------------------------------------------------------ 6 and 7. bounded, finite input
def _make_map_env(spec):
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    return gym.make("Dubins4DMapGuarded-v0", map=spec)


@pytest.mark.parametrize("radius", [1e150, 1e300, 10**400])
def test_a_map_number_too_large_for_the_geometry_is_refused(tmp_path, radius):
    from rmm_envs.systems.dubins4d_map.shape_map import MapError

    path = tmp_path / "big.json"
    path.write_text(f'[{{"circle": [0, 0, {radius}]}}]')
    with pytest.raises(
        MapError, match=r"entry 0 .*with numbers of magnitude at most 1e\+09 \(larger ones overflow the geometry\)"
    ):
        _make_map_env(str(path))


def test_map_files_bounded_in_bytes_and_depth_before_they_are_parsed(tmp_path):
    from rmm_envs.systems.dubins4d_map.shape_map import MapError
    from rmm_envs.worlds.bounds import MAX_MAP_BYTES

    big = tmp_path / "big.json"
    big.write_text('[{"circle": [0, 0, 1]}' + " " * MAX_MAP_BYTES + "]")
    with pytest.raises(MapError, match=f"map file '{big}' holds more than 16 MiB"):
        _make_map_env(str(big))
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(MapError, match=f"map file '{deep}' nests its JSON too deeply"):
        _make_map_env(str(deep))
    digits = tmp_path / "digits.json"
    digits.write_text('[{"circle": [0, 0, 1' + "0" * 5000 + "]}]")
    with pytest.raises(MapError, match=f"map file '{digits}' holds a number that cannot be read"):
        _make_map_env(str(digits))


def _star(n, scale=3.0):
    import numpy as np

    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = scale * (1 + 0.3 * np.sin(7 * a))
    return np.column_stack([r * np.cos(a), r * np.sin(a)]).tolist()


def test_a_polygon_of_thousands_of_vertices_builds_in_seconds_and_larger_ones_are_refused():
    import time

    from rmm_envs.systems.dubins4d_map.shape_map import MapError
    from rmm_envs.worlds.bounds import MAX_POLYGON_VERTICES

    t0 = time.perf_counter()
    env = _make_map_env(
        [{"polygon": _star(2000)}]
    )  # the finding: 29 s, the simplicity check and ear clipping quadratic in Python
    took = time.perf_counter() - t0
    obs, _ = env.reset(seed=0)
    assert took < 10.0, f"gym.make took {took:.1f} s"
    env.close()
    with pytest.raises(
        MapError, match=f"expected at most {MAX_POLYGON_VERTICES:,} vertices, got {MAX_POLYGON_VERTICES + 2:,}"
    ):
        _make_map_env([{"polygon": _star(MAX_POLYGON_VERTICES + 2)}])


def test_the_vectorised_polygon_checks_agree_with_the_scalar_tests():
    """Every pair of edges of small polygons (convex, star-shaped, self-crossing, with collinear
    and repeated points) judged by the vectorised test equals the scalar one."""
    import numpy as np

    from rmm_envs.systems.dubins4d_map.shape_map import _segments_meet, _segments_meet_many

    rng = np.random.default_rng(3)
    for _ in range(200):
        pts = rng.integers(-3, 4, (8, 2)).astype(float)
        ends = np.roll(pts, -1, axis=0)
        for i in range(8):
            got = _segments_meet_many(pts[i], ends[i], pts, ends)
            want = [_segments_meet(pts[i], ends[i], pts[j], ends[j]) for j in range(8)]
            assert got.tolist() == want


@pytest.mark.parametrize(
    "env_id, option, value",
    [
        ("Dubins4DGuarded-v0", "state", [1e300, 1e300, 0, 1]),
        ("Dubins4DGuarded-v0", "state", [2e9, 0, 0, 1]),
        ("Dubins4DGuarded-v0", "goal", [0, 0, 1e200]),
        ("Dubins4DGuarded-v0", "obstacles", [[0, 0, 1e150]]),
    ],
)
def test_reset_options_too_large_for_the_geometry_are_refused(env_id, option, value):
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    env = gym.make(env_id)
    with pytest.raises(ValueError, match=f"option '{option}' must be .*magnitude at most 1e\\+09"):
        env.reset(seed=0, options={option: value})
    obs, _ = env.reset(seed=0, options={"state": [1e9, 0, 0, 1]})  # the bound itself: finite observations
    import numpy as np

    assert np.all(np.isfinite(obs))
    env.close()


def test_quadrotor_velocity_too_large_is_refused():
    import gymnasium as gym
    import numpy as np

    import rmm_envs  # noqa: F401

    env = gym.make("QuadrotorRoom-v0")
    env.reset(seed=0)
    state = np.array(
        env.unwrapped.privileged()["state"], dtype=float
    )  # position, quaternion xyzw, velocity, angular velocity
    state[7] = 1e200  # the x velocity
    with pytest.raises(ValueError, match=r"option 'state' must be 13 numbers of magnitude at most 1e\+09"):
        env.reset(seed=0, options={"state": state.tolist()})
    env.close()


@pytest.mark.parametrize("rows", [10**6, 10**400, 33])
def test_maze_sizes_refused_before_anything_is_allocated(rows):
    import time

    import gymnasium as gym
    import numpy as np

    import rmm_envs  # noqa: F401
    from rmm_envs.systems.maze.mazes import generate_maze

    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=r"maze_rows must be an integer in \[2, 32\]"):
        gym.make("Dubins3DMazeParallel-v0", maze_rows=rows)
    with pytest.raises(ValueError, match=r"rows and cols must be integers in \[2, 32\]"):
        generate_maze(np.random.default_rng(0), rows=rows, cols=3)
    assert time.perf_counter() - t0 < 5.0


def test_a_file_size_limit_error_names_the_file_the_limit_and_the_fix(monkeypatch):
    """The line both commands print for EFBIG (the drills below run them under a real limit)."""
    import errno

    from rmm_envs import os_errors as failures

    e = OSError(errno.EFBIG, "File too large", "d/shard_0001.npz")
    monkeypatch.setattr(failures, "file_size_limit", lambda: 4096)
    assert failures.describe_os_error(e) == (
        "d/shard_0001.npz reached the file-size limit (ulimit -f: 4096 bytes); raise it "
        "(ulimit -f unlimited), then what is stored is kept: rerun the same command",
        1,
    )
    monkeypatch.setattr(failures, "file_size_limit", lambda: None)
    assert failures.describe_os_error(OSError(errno.EFBIG, "File too large"), path="out")[0].startswith(
        "out reached the file-size limit; raise it"
    )


@pytest.mark.slow
def test_datagen_under_a_file_size_limit_is_one_line_exit_1_and_a_rerun_finishes(tmp_path):
    """The worker writing a shard hits the limit (EFBIG, as ENOSPC would): one line naming the
    directory and the fix, exit 1, and the same command afterwards finishes the dataset.  In
    the slow tier: rmm-bench's drill above runs in the default suite, this one costs two
    commands with two workers each."""
    out = tmp_path / "d"
    cmd = [
        sys.executable,
        "-m",
        "rmm_envs.risk.datagen",
        "--configs",
        "4",
        "--samples-per-config",
        "50",
        "--branches",
        "3",
        "--depth",
        "1",
        "--configs-per-shard",
        "2",
        "--out",
        str(out),
        "--no-progress",
        "--workers",
        "2",
    ]

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300, preexec_fn=limit)
    assert res.returncode == 1, res.stderr
    assert _one_line(res.stderr) == (
        f"rmm-datagen: error: {out} reached the file-size limit (ulimit -f: 4096 bytes); raise "
        "it (ulimit -f unlimited), then what is stored is kept: rerun the same command"
    )
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert "200 labelled samples" in done.stdout


def test_a_closed_output_pipe_is_not_called_an_unreachable_ray_cluster():
    """``rmm-bench report dir | head -1``: the reader closes the pipe, print raises BrokenPipeError
    (a ConnectionError, as the Ray check's are); the line says what happened."""
    import errno

    from rmm_envs.os_errors import describe_os_error

    line, status = describe_os_error(BrokenPipeError(errno.EPIPE, "Broken pipe"))
    assert (line, status) == (
        "Broken pipe: the output was closed before the command finished writing it (a reader such "
        "as `| head` that stops early); what is stored is kept: rerun the same command",
        1,
    )


def test_an_unreachable_ray_cluster_is_one_line_exit_1_within_seconds(tmp_path, capsys):
    """Port 1 of this host refuses connections: ray.init alone would retry for minutes."""
    import time

    from rmm_envs.risk.datagen import main as datagen

    t0 = time.perf_counter()
    assert (
        main(
            [
                "--agent",
                "inactive",
                "--episodes",
                "1",
                "--backend",
                "ray",
                "--ray-address",
                "127.0.0.1:1",
                "--out",
                str(tmp_path / "r"),
                "--clock",
                "fixed:1",
                "--no-progress",
            ]
        )
        == 1
    )
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("rmm-bench: error: cannot reach the Ray cluster at 127.0.0.1:1 (ConnectionRefusedError")
    assert line.endswith(
        "check the address (--ray-address) or leave it out to start a local Ray, then what is stored is "
        "kept: rerun the same command"
    )
    assert (
        datagen(
            [
                "--configs",
                "2",
                "--samples-per-config",
                "2",
                "--branches",
                "2",
                "--depth",
                "1",
                "--out",
                str(tmp_path / "d"),
                "--no-progress",
                "--backend",
                "ray",
                "--ray-address",
                "ray://127.0.0.1:1",
            ]
        )
        == 1
    )
    assert _one_line(capsys.readouterr().err).startswith(
        "rmm-datagen: error: cannot reach the Ray cluster at ray://127.0.0.1:1"
    )
    assert time.perf_counter() - t0 < 60


@pytest.mark.parametrize(
    "env_id, kwargs, name",
    [
        ("Dubins4DGuarded-v0", {"ray_length": 1e300}, "ray_length"),  # the finding: infinite observations
        ("Dubins4DGuarded-v0", {"step_dt": 1e300}, "step_dt"),
        ("Dubins4DGuarded-v0", {"n_rays": 10**400}, "n_rays"),  # an OverflowError traceback before
        ("Dubins3DMazeParallel-v0", {"speed": 1e200}, "speed"),
        ("QuadrotorRoomParallel-v0", {"cruise_speed": 1e200}, "cruise_speed"),
    ],
)
def test_constructor_arguments_too_large_for_the_arithmetic_are_refused_by_name(env_id, kwargs, name):
    import gymnasium as gym

    import rmm_envs  # noqa: F401

    with pytest.raises(
        ValueError,
        match=rf"^{name} must be .* \(at most 1e\+09 in magnitude: larger values overflow "
        r"the arithmetic\), got ",
    ):
        gym.make(env_id, **kwargs)
