"""rmm-bench's typed configuration: stored format unchanged, env contract, guardian threads."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.config import AgentRun, BenchConfig, EpisodeResult, EpisodeTask, accepts_argument, run_key
from rmm_bench.run_args import parse_run, parse_sweep
from rmm_bench.store import EPISODE_FIELDS

DATA = Path(__file__).parent / "data"
# tables and the database only: the figure has its own tests (test_bench, test_cli_figures)
FAST = ["--clock", "fixed:1", "--no-progress", "--workers", "1", "--no-figure"]


# ------------------------------------------------------------------ the stored format
def test_run_keys_and_stored_config_are_those_of_the_untyped_harness(capsys):
    # keys and configs as written by the dict-based harness (tests/data/bench_results_v0.db)
    con = sqlite3.connect(DATA / "bench_results_v0.db")
    stored = {
        agent: (key, json.loads(cfg)) for key, agent, cfg in con.execute("SELECT run_key, agent, config FROM runs")
    }
    con.close()
    assert stored["inactive"][0] == "3990ef051d980703" and stored["random"][0] == "c731fab8951b5132"
    par = parse_run(["--agent", "inactive,brakes", "--episodes", "3", "--out", "olddb", *FAST], "")
    circ = parse_run(
        [
            "--agent",
            "random",
            "--agent-opt",
            "random.p_active=0.5",
            "--env",
            "Dubins4DGuarded-v0",
            "--episodes",
            "2",
            "--out",
            "olddb",
            *FAST,
        ],
        "",
    )
    runs = par.agent_runs() | circ.agent_runs()
    assert set(runs) == set(stored)
    for agent, run in runs.items():
        assert run.as_dict() == stored[agent][1]
        assert run.key == stored[agent][0] == run_key(stored[agent][1])
    assert circ.env_kwargs == {"clock": "fixed:1"}  # the blocking env takes no time_accel / base_step
    assert par.env_kwargs == {"time_accel": 10.0, "base_step": 0.1, "clock": "fixed:1"}
    assert capsys.readouterr().err == ""


def test_old_database_reports_the_same_table_and_resume_runs_nothing(tmp_path, capsys):
    out = tmp_path / "olddb"
    out.mkdir()
    shutil.copy(DATA / "bench_results_v0.db", out / "results.db")
    assert main(["report", str(out), "--invocation", "1", "--invocation", "2"]) == 0
    assert (out / "table_I.md").read_text() == (DATA / "bench_results_v0_table.md").read_text()
    con = sqlite3.connect(out / "results.db")
    before = con.execute("SELECT * FROM episodes ORDER BY run_key, episode").fetchall()
    assert main(["--agent", "inactive,brakes", "--episodes", "3", "--out", str(out), *FAST, "--resume"]) == 0
    after = con.execute("SELECT * FROM episodes ORDER BY run_key, episode").fetchall()
    # every episode was done: the rows are unchanged (the resume migrated the file: later columns appended, NULL)
    assert [a[: len(b)] for a, b in zip(after, before, strict=True)] == before
    assert all(v is None for a, b in zip(after, before, strict=True) for v in a[len(b) :])
    ((args, keys, status),) = con.execute("SELECT args, run_keys, status FROM invocations WHERE id = 3").fetchall()
    assert json.loads(keys) == {"inactive": "3990ef051d980703", "brakes": "c70cfd4516eee295"} and status == "finished"
    (old_args,) = con.execute("SELECT args FROM invocations WHERE id = 1").fetchone()
    # the invocation records the same arguments, and the options added since
    assert set(json.loads(args)) == set(json.loads(old_args)) | {"no_figure", "shard"}
    con.close()
    capsys.readouterr()
    # the run recorded before the ids settled (1) and its rerun (3) are one configuration, headed by today's id
    assert main(["report", str(out), "--invocation", "1", "--invocation", "3"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("Table I: Dubins4DParallel-v0, clock fixed:1, time accel 10.0, seed 0, 3 episodes")
    assert "configurations" not in text and text.count("Dubins4DParallel-v0") == 1
    assert (out / "table_I.csv").read_text().startswith("agent,")  # one configuration: no configuration columns


def test_episode_result_fields_are_the_store_columns():
    assert [f.name for f in dataclasses.fields(EpisodeResult)] == list(EPISODE_FIELDS)
    r = EpisodeResult(run_key="k", episode=1, agent="a", seed=2, outcome="goal", steps=3)
    assert r.as_row() == {
        **dict.fromkeys(EPISODE_FIELDS),
        "run_key": "k",
        "episode": 1,
        "agent": "a",
        "seed": 2,
        "outcome": "goal",
        "steps": 3,
    }
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.outcome = "error"
    # the schema derived from the dataclass is the one every results.db was written with
    assert EPISODE_FIELDS == {
        "run_key": "TEXT NOT NULL",
        "episode": "INTEGER NOT NULL",
        "agent": "TEXT NOT NULL",
        "seed": "INTEGER NOT NULL",
        "outcome": "TEXT NOT NULL",
        "steps": "INTEGER",
        "active_steps": "INTEGER",
        "sim_time": "REAL",
        "active_sim_time": "REAL",
        "compute_time": "REAL",
        "avg_compute_time": "REAL",
        "decision_mean": "REAL",
        "decision_std": "REAL",
        "decision_max": "REAL",
        "precompute_time": "REAL",
        "final_speed": "REAL",
        "cum_reward": "REAL",
        "qp_fallbacks": "INTEGER",
        "nan_states": "INTEGER",
        "guardian_stats": "TEXT",
        "error": "TEXT",
        "wall_time": "REAL",
        "finished": "REAL",
        "error_kind": "TEXT",
        "cost": "REAL",
        "start": "TEXT",
    }


def test_configs_are_frozen_copies_and_refuse_what_cannot_be_stored():
    kw = {"grid_n": [8, 8]}
    run = AgentRun("hj", kw, "Dubins4DParallel-v0", {"clock": "fixed:1"}, 0, 600.0, False)
    kw["grid_n"].append(9)
    assert run.agent_kwargs == {"grid_n": [8, 8]}  # a copy: the caller's dict does not reach the run
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.seed = 1
    with pytest.raises(ValueError, match="agent_kwargs must hold JSON values.*object"):
        AgentRun("hj", {"x": object()}, "E", {}, 0, 1.0, False)


def test_sweep_derives_one_config_per_latency_without_changing_its_own():
    cfg = parse_sweep(["--agent", "inactive", "--latency", "0,2.5", "--out", "s", "--no-progress"])
    assert cfg.latencies == (0.0, 2.5) and cfg.clock == "fixed:0" and cfg.env_kwargs["clock"] == "fixed:0"
    at = cfg.with_clock("fixed:2.5")
    assert at.env_kwargs == {"time_accel": 10.0, "base_step": 0.1, "clock": "fixed:2.5"} and at.clock == "fixed:2.5"
    assert cfg.clock == "fixed:0" and cfg.env_kwargs["clock"] == "fixed:0"
    assert at.agent_runs()["inactive"].key != cfg.agent_runs()["inactive"].key


# ------------------------------------------------------------------ the env contract
def test_envs_without_the_parallel_autonomy_contract_are_refused_by_name(tmp_path, capsys):
    assert main(["--agent", "inactive", "--env", "Dubins3DMaze-v0", "--out", str(tmp_path / "m"), *FAST]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "--env Dubins3DMaze-v0: rmm-bench runs guardians only on envs offering the parallel-autonomy contract" in err
    assert "takes no `clock`" in err and "its action space is Box(" in err and "'active_ctrl'" in err
    assert err.endswith(
        "; its system's guardian envs are Dubins3DMazeParallel-v0 (non-blocking) and Dubins3DMazeGuarded-v0 (blocking)"
    )
    assert main(["--agent", "inactive", "--env", "CartPole-v1", "--out", str(tmp_path / "c"), *FAST]) == 2
    err = capsys.readouterr().err
    assert "CartPole-v1 does not: its constructor takes no `clock`" in err
    assert err.endswith(
        "; its system's guardian envs are CartPoleParallel-v0 (non-blocking) and CartPoleGuarded-v0 (blocking)\n"
    )  # CartPole-v1 is the dynamics the table's CartPole system guards
    assert main(["--agent", "inactive", "--env", "Acrobot-v1", "--out", str(tmp_path / "a"), *FAST]) == 2
    assert capsys.readouterr().err.endswith(
        "; rmm_envs.envs.any_env.parallel(env, driver, safe_default, success) makes "
        'a guardian env of it (docs/tutorials/own-simulator.md, "The env\'s arguments")\n'
    )
    assert not (tmp_path / "m").exists() and not (tmp_path / "c").exists()


def test_the_blocking_env_runs_through_the_same_contract(tmp_path, capsys):
    out = tmp_path / "b"
    assert main(["--agent", "brakes", "--env", "Dubins4DGuarded-v0", "--episodes", "2", "--out", str(out), *FAST]) == 0
    con = sqlite3.connect(out / "results.db")
    rows = con.execute("SELECT outcome, steps, compute_time, final_speed FROM episodes").fetchall()
    assert len(rows) == 2 and all(
        o != "error" and s > 0 and c == pytest.approx(s * 1e-3) and v is not None for o, s, c, v in rows
    )
    capsys.readouterr()


def test_env_statistics_contract_is_checked_and_optional_keys_may_be_absent():
    from rmm_bench.runner import EPISODE_STATISTICS, EnvContractError, _statistics

    ep = {k: i for i, k in enumerate(EPISODE_STATISTICS.values())}
    got = _statistics("E-v0", {"outcome": "goal", "episode_stats": ep})
    assert got == {
        "outcome": "goal",
        "final_speed": None,
        "cost": None,
        **{c: ep[k] for c, k in EPISODE_STATISTICS.items()},
    }
    assert _statistics("E-v0", {"outcome": "goal", "episode_stats": ep | {"final_speed": 1.5}})["final_speed"] == 1.5
    assert _statistics("E-v0", {"outcome": "goal", "episode_stats": ep | {"cum_cost": 1.0}})["cost"] == 1.0
    with pytest.raises(
        EnvContractError, match=r"env E-v0 ended an episode without info\[\"episode_stats\"\] keys \['cum_reward'\]"
    ):
        _statistics("E-v0", {"outcome": "goal", "episode_stats": {k: v for k, v in ep.items() if k != "cum_reward"}})
    with pytest.raises(EnvContractError, match=r"without info keys \['outcome', 'episode_stats'\]"):
        _statistics("E-v0", {})


# ------------------------------------------------------------------ guardian threads
class _Base:
    def __init__(self, threads: int | None = None, cache_dir=None):
        self.threads = threads


class _Forwards(_Base):
    def __init__(self, margin: float = 0.0, **kwargs):
        super().__init__(**kwargs)


class _Swallows:
    def __init__(self, **kwargs):
        pass


def test_accepts_argument_reads_signatures_and_follows_forwarded_kwargs():
    assert accepts_argument(_Base, "threads") and accepts_argument(_Forwards, "threads")
    assert not accepts_argument(_Swallows, "threads") and not accepts_argument(_Forwards, "delay")
    assert accepts_argument(lambda *, threads=None: None, "threads")
    assert not accepts_argument(lambda threads_n=None: None, "threads") and not accepts_argument(len, "threads")


@pytest.mark.parametrize(
    "workers, backend, opts, expected",
    [(2, "local", {}, 1), (1, "ray", {}, 1), (1, "local", {}, None), (4, "local", {"threads": 3}, None)],
)
def test_threads_go_to_guardians_that_take_them_when_workers_share_the_machine(workers, backend, opts, expected):
    from rmm_bench.run_plan import guardian_threads

    assert guardian_threads("tests.bench_helpers:Threaded", opts, workers, backend) == expected
    assert guardian_threads("inactive", {}, workers, backend) is None  # takes no threads


def test_a_worker_builds_the_guardian_with_the_tasks_threads_and_sets_no_environment(tmp_path, monkeypatch):
    from rmm_bench.run_plan import plan_tasks
    from rmm_bench.runner import run_episode
    from rmm_bench.store import ResultsStore

    monkeypatch.delenv("RMM_HJ_THREADS", raising=False)
    cfg = parse_run(
        [
            "--agent",
            "tests.bench_helpers:Threaded,inactive",
            "--agent-opt",
            "tests.bench_helpers:Threaded.margin=0.5",
            "--episodes",
            "1",
            "--out",
            str(tmp_path),
            "--clock",
            "fixed:1",
            "--workers",
            "2",
        ],
        "",
    )
    store = ResultsStore(tmp_path / "results.db")
    tasks = plan_tasks(store, cfg.agent_runs(), 1, workers=2, backend="local")
    store.close()
    assert [(t.agent, t.threads) for t in tasks] == [("tests.bench_helpers:Threaded", 1), ("inactive", None)]
    assert tasks[0].guardian_kwargs() == {"margin": 0.5, "threads": 1}
    assert tasks[0].run_key == cfg.agent_runs()["tests.bench_helpers:Threaded"].key  # threads are not part of the run
    result = run_episode(tasks[0])
    assert result.outcome != "error", result.error
    assert json.loads(result.guardian_stats) == {"threads": 1, "env_threads": -1}
    assert "RMM_HJ_THREADS" not in __import__("os").environ
    alone = dataclasses.replace(tasks[0], threads=None)
    assert json.loads(run_episode(alone).guardian_stats) == {"threads": 0, "env_threads": -1}


def test_bench_config_is_what_the_command_line_said():
    cfg = parse_run(
        [
            "--agent",
            "lrmm,cbf",
            "--agent-opt",
            "cbf.p1=2",
            "--seed",
            "3",
            "--out",
            "o",
            "--workers",
            "2",
            "--clock",
            "cpu",
            "--time-accel",
            "5",
        ],
        "",
    )
    assert isinstance(cfg, BenchConfig)
    assert (cfg.agents, cfg.agent_kwargs, cfg.seed, cfg.workers, cfg.clock) == (
        ("lrmm", "cbf"),
        {"cbf": {"p1": 2}},
        3,
        2,
        "cpu",
    )
    assert cfg.env_kwargs == {"time_accel": 5.0, "base_step": 0.1, "clock": "cpu"} and cfg.progress
    assert cfg.parsed["agent_opt"] == ["cbf.p1=2"] and cfg.parsed["clock"] == "cpu"
    task = EpisodeTask(run=cfg.agent_runs()["cbf"], run_key="k", episode=0, seed=1)
    assert task.guardian_kwargs() == {"p1": 2} and task.agent == "cbf"


def test_each_guardian_class_is_resolved_once_per_command(monkeypatch, tmp_path):
    # --agent resolves each name to its class once; the checks and the task plan use that class
    import rmm_bench.run_checks
    import rmm_bench.run_plan
    import rmm_guardians.registry as registry
    from rmm_bench.run_plan import applicable, plan_tasks
    from rmm_bench.store import ResultsStore
    from tests.bench_helpers import Threaded

    calls = []
    resolve = registry.load_guardian_class

    def counted(name):
        calls.append(name)
        return resolve(name)

    for module in (registry, rmm_bench.run_checks, rmm_bench.run_plan):  # where each caller looks it up
        monkeypatch.setattr(module, "load_guardian_class", counted)
    cfg = parse_run(
        [
            "--agent",
            "tests.bench_helpers:Threaded,inactive",
            "--episodes",
            "1",
            "--out",
            str(tmp_path),
            "--clock",
            "fixed:1",
            "--no-progress",
            "--workers",
            "2",
        ],
        "",
    )
    assert calls == ["tests.bench_helpers:Threaded", "inactive"]
    assert cfg.agent_classes == {"tests.bench_helpers:Threaded": Threaded, "inactive": resolve("inactive")}
    cfg, meta = applicable(cfg)
    store = ResultsStore(tmp_path / "results.db")
    tasks = plan_tasks(store, cfg.agent_runs(), 1, cfg.workers, cfg.backend, classes=cfg.agent_classes)
    store.close()
    assert calls == ["tests.bench_helpers:Threaded", "inactive"]  # neither the checks nor the plan resolved again
    assert set(meta) == {"tests.bench_helpers:Threaded", "inactive"} and [t.threads for t in tasks] == [1, None]
    assert dataclasses.replace(cfg, agent_classes={}) == cfg  # not part of the configuration's identity


def test_the_non_blocking_defaults_are_the_wrapper_s_everywhere():
    import inspect

    from rmm_bench.run_args import NON_BLOCKING_DEFAULTS
    from rmm_bench.run_checks import _env_creator
    from rmm_envs.wrappers.nonblocking import BASE_STEP, TIME_ACCEL, NonBlockingStepping

    assert (TIME_ACCEL, BASE_STEP) == (10.0, 0.1)  # the paper's 10x and 0.1 s
    assert NON_BLOCKING_DEFAULTS == {"time_accel": TIME_ACCEL, "base_step": BASE_STEP}
    for factory in (NonBlockingStepping, _env_creator("Dubins4DParallel-v0"), _env_creator("QuadrotorRoomParallel-v0")):
        params = inspect.signature(factory).parameters
        assert (params["time_accel"].default, params["base_step"].default) == (TIME_ACCEL, BASE_STEP)
    cfg = parse_run(["--agent", "inactive", "--out", "x", *FAST], "")
    assert (cfg.env_kwargs["time_accel"], cfg.env_kwargs["base_step"]) == (TIME_ACCEL, BASE_STEP)


def test_no_function_of_the_packages_writes_its_own_non_blocking_default():
    """TIME_ACCEL and BASE_STEP have one owner: a parameter ``time_accel`` or ``base_step`` defaults to
    them (or to None, "the env's own"), never to a number of its own."""
    import ast

    root = Path(__file__).resolve().parents[1]
    found = []
    for path in sorted(p for pkg in ("rmm_envs", "guardians", "benchmarks") for p in (root / pkg).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = node.args.posonlyargs + node.args.args
                pairs = [
                    # defaults belong to the last positional arguments; kw_defaults has one entry (or None) per kw-only one
                    *zip(args[len(args) - len(node.args.defaults) :], node.args.defaults, strict=True),
                    *zip(node.args.kwonlyargs, node.args.kw_defaults, strict=True),
                ]
                found += [
                    f"{path.relative_to(root)}:{node.lineno} {node.name}({a.arg}={d.value!r})"
                    for a, d in pairs
                    if a.arg in ("time_accel", "base_step") and isinstance(d, ast.Constant) and d.value is not None
                ]
    assert found == []
