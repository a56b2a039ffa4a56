"""Fault drills for the data and environment side: damaged shards, bad sizes and parameters,
partial reset options, and results that must not depend on the order episodes run in."""

import hashlib
import json
import math
import shlex
import sqlite3
import struct
import warnings

import gymnasium as gym
import numpy as np
import pyarrow.parquet as pq
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset
from rmm_envs.risk.datagen import main as datagen_main
from rmm_envs.risk.estimator import MAX_TREE_NODES, RiskEstimator, tree_nodes
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv

TINY = dict(configs=4, samples_per_config=6, branches=4, depth=2, configs_per_shard=2, seed=11)


def tiny(**kw):
    return DatagenConfig(**(TINY | kw))


def _flip_middle(path):
    """Flip bytes in the middle of a shard's data pages, leaving its footer (row count) intact."""
    data = bytearray(path.read_bytes())
    rows = pq.read_metadata(path).num_rows
    mid = len(data) // 2
    for i in range(mid, mid + 8):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))
    assert pq.read_metadata(path).num_rows == rows  # the damage is invisible to a row count
    return rows


# ---------------------------------------------------------------------- shard integrity
def test_rerun_regenerates_a_shard_with_flipped_bytes_instead_of_laundering_it(tmp_path, capsys):
    out = tmp_path / "d"
    first = generate(tiny(), out, workers=1, progress=False)
    ref = load_dataset(out)
    shard = out / "shard-00001.parquet"
    _flip_middle(shard)
    capsys.readouterr()
    again = generate(tiny(), out, workers=1, progress=False)
    assert again["last_run"]["regenerated"] == ["shard-00001.parquet"]
    assert again["last_run"]["new_rows"] == 12
    assert "shard-00001.parquet" in capsys.readouterr().err
    assert again["dataset_sha256"] == first["dataset_sha256"]
    fixed = load_dataset(out)
    for field in ("obs", "state", "risk", "min_risk_ctrl", "min_risk_ctrl_dur", "n_leaves", "config_id"):
        np.testing.assert_array_equal(getattr(fixed, field), getattr(ref, field))


def test_load_refuses_flipped_bytes_in_one_line_naming_the_file_and_the_fix(tmp_path):
    out = tmp_path / "d"
    generate(tiny(), out, workers=1, progress=False)
    _flip_middle(out / "shard-00000.parquet")
    with pytest.raises(ValueError) as e:
        load_dataset(out)
    msg = str(e.value)
    assert "\n" not in msg and str(out / "shard-00000.parquet") in msg
    # the exact command that repairs it
    assert (
        "rmm-datagen --env Dubins4DGuarded-v0 --configs 4 --samples-per-config 6 --seed 11 "
        "--configs-per-shard 2 --branches 4 --depth 2" in msg
    )
    assert f"--out {out}" in msg
    # and that command does repair it
    cmd = shlex.split(msg.split("`")[1])[1:]
    assert datagen_main(cmd + ["--workers", "1", "--no-progress"]) == 0
    load_dataset(out)


def test_damaged_shard_of_an_interrupted_run_is_regenerated(tmp_path):
    """No manifest yet (the run was killed): the shard's own checksum file vouches for it."""
    out = tmp_path / "d"
    generate(tiny(), out, workers=1, progress=False)
    ref = load_dataset(out).risk
    (out / "manifest.json").unlink()
    for s in (0, 1):  # what an interrupted run leaves: shards and their checksum files
        shard = out / f"shard-0000{s}.parquet"
        (out / f"shard-0000{s}.sha256").write_text(f"{hashlib.sha256(shard.read_bytes()).hexdigest()}  {shard.name}\n")
    _flip_middle(out / "shard-00000.parquet")
    man = generate(tiny(), out, workers=1, progress=False)
    assert man["last_run"]["regenerated"] == ["shard-00000.parquet"]
    assert not list(out.glob("*.sha256"))  # folded into the manifest
    np.testing.assert_array_equal(load_dataset(out).risk, ref)


def test_shard_without_any_recorded_checksum_is_not_trusted(tmp_path):
    out = tmp_path / "d"
    generate(tiny(), out, workers=1, progress=False)
    ref = load_dataset(out).risk
    (out / "manifest.json").unlink()
    _flip_middle(out / "shard-00001.parquet")
    man = generate(tiny(), out, workers=1, progress=False)
    assert sorted(man["last_run"]["regenerated"]) == ["shard-00000.parquet", "shard-00001.parquet"]
    np.testing.assert_array_equal(load_dataset(out).risk, ref)


def test_truncated_shard_named_on_load_and_regenerated_on_rerun(tmp_path):
    out = tmp_path / "d"
    generate(tiny(), out, workers=1, progress=False)
    ref = load_dataset(out).risk
    shard = out / "shard-00001.parquet"
    shard.write_bytes(shard.read_bytes()[: shard.stat().st_size // 2])
    with pytest.raises(ValueError, match=r"shard-00001\.parquet does not match its checksum.*rerun `rmm-datagen"):
        load_dataset(out)
    man = generate(tiny(), out, workers=1, progress=False)
    assert man["last_run"]["regenerated"] == ["shard-00001.parquet"]
    np.testing.assert_array_equal(load_dataset(out).risk, ref)


def test_corrupt_manifest_or_missing_entry_gives_one_line(tmp_path):
    out = tmp_path / "d"
    generate(tiny(), out, workers=1, progress=False)
    manifest = out / "manifest.json"
    good = manifest.read_text()
    manifest.write_text(good[: len(good) // 2])
    with pytest.raises(ValueError) as e:
        load_dataset(out)
    assert str(manifest) in str(e.value) and "rerun `rmm-datagen" in str(e.value) and "\n" not in str(e.value)
    # a manifest that silently drops a shard would load half the data
    m = json.loads(good)
    del m["shards"]["shard-00001.parquet"]
    manifest.write_text(json.dumps(m))
    with pytest.raises(ValueError, match=r"does not list the shards.*shard-00001\.parquet"):
        load_dataset(out)
    # the rerun repairs both: the damaged manifest's checksums are not trusted, shards are redone
    man = generate(tiny(), out, workers=1, progress=False)
    assert man["last_run"]["regenerated"] == ["shard-00001.parquet"]
    assert len(load_dataset(out)) == 24


# ---------------------------------------------------------------------- sizes and workers
def test_tree_size_refused_before_allocation_naming_the_flags(tmp_path, capsys):
    assert datagen_main(["--branches", "32", "--depth", "6", "--out", str(tmp_path / "big"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert "--branches" in err and "--depth" in err and "= 32" in err and "= 6" in err
    assert "1,108,378,656 nodes" in err  # 32 + 32^2 + ... + 32^6
    assert not (tmp_path / "big").exists()  # refused before anything was written
    assert tree_nodes(32, 2) == 1056 and tree_nodes(1, 7) == 7 and tree_nodes(2, 100) == math.inf
    with pytest.raises(ValueError, match="more than 2\\^64"):
        tiny(branches=2, depth=10**9).validate()
    env = Dubins4DGuardedEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="--depth"):
        RiskEstimator(env.risk_scene(), branches=2, depth=21)  # 2^22 - 2 nodes
    RiskEstimator(env.risk_scene(), branches=2, depth=19)  # 2^20 - 2 nodes: the largest accepted
    assert tree_nodes(2, 19) <= MAX_TREE_NODES < tree_nodes(2, 20)


@pytest.mark.parametrize("workers", [0, -1])
def test_datagen_workers_zero_or_negative_refused(tmp_path, capsys, workers):
    assert (
        datagen_main(
            [
                "--workers",
                str(workers),
                "--configs",
                "1",
                "--samples-per-config",
                "2",
                "--branches",
                "2",
                "--out",
                str(tmp_path / "w"),
                "--no-progress",
            ]
        )
        == 2
    )
    err = capsys.readouterr().err
    assert "--workers" in err and f"got {workers}" in err
    assert not list((tmp_path / "w").glob("shard-*"))


# ---------------------------------------------------------------------- reset options
GOAL_AT_ORIGIN = [0.0, 0.0, 1.0]
STATE_AT_ORIGIN = [0.0, 0.0, 0.0, 1.0]


def _rules_hold(scene, state):
    obst, goal = scene.obstacles, scene.goal
    assert not (np.hypot(*(obst[:, :2] - state[:2]).T) <= obst[:, 2]).any(), "start inside an obstacle"
    assert np.hypot(*(state[:2] - goal[:2])) > goal[2], "start inside the goal"
    assert not (np.hypot(*(obst[:, :2] - goal[:2]).T) + goal[2] < obst[:, 2]).any(), "goal entirely inside an obstacle"


@pytest.mark.parametrize(
    "options",
    [
        {"goal": GOAL_AT_ORIGIN},
        {"state": STATE_AT_ORIGIN},
        {"state": STATE_AT_ORIGIN, "goal": [6.0, -3.0, 0.5]},
        {"obstacles": [[3.0, 3.0, 4.0]], "goal": [3.0, 3.0, 5.0]},
    ],
)
def test_dubins4d_partial_options_are_generated_around_for_every_seed(options):
    env = Dubins4DGuardedEnv()
    for seed in range(60):
        _, info = env.reset(seed=seed, options=options)
        for key, value in options.items():
            got = {"state": info["state"], "goal": env.scene.goal, "obstacles": env.scene.obstacles}[key]
            np.testing.assert_array_equal(got, np.asarray(value, float).reshape(got.shape))
        _rules_hold(env.scene, info["state"])


def test_dubins4d_given_state_keeps_generation_where_it_fits_and_redraws_where_it_does_not():
    """A seed whose generated obstacles leave the given state free gets exactly them; a seed whose
    obstacles cover it gets the next draw that leaves it free (the draws continue from the seed)."""
    env, plain = Dubins4DGuardedEnv(), Dubins4DGuardedEnv()
    state = np.array([1.0, -1.0, 0.0, 1.0])
    kept = redrawn = 0
    for seed in range(40):
        plain.reset(seed=seed)
        covered = (np.hypot(*(plain.scene.obstacles[:, :2] - state[:2]).T) <= plain.scene.obstacles[:, 2]).any()
        _, info = env.reset(seed=seed, options={"state": state})
        _rules_hold(env.scene, info["state"])
        if covered:
            redrawn += 1
            assert not np.array_equal(env.scene.obstacles, plain.scene.obstacles)
        else:
            kept += 1
            np.testing.assert_array_equal(env.scene.obstacles, plain.scene.obstacles)
    assert kept >= 5 and redrawn >= 5


def test_dubins4d_explicit_options_obey_generation_rules_and_errors_blame_only_given_values():
    env = Dubins4DGuardedEnv()
    with pytest.raises(ValueError, match=r"option 'goal' .* entirely inside obstacle 0 .* of option 'obstacles'"):
        env.reset(seed=0, options={"goal": [0.0, 0.0, 0.5], "obstacles": [[0.0, 0.0, 3.0]]})
    # the boundary case: a goal that touches the obstacle's rim from inside is not *entirely* inside
    env.reset(seed=0, options={"goal": [0.0, 0.0, 0.5], "obstacles": [[0.5, 0.0, 1.0]]})
    for goal in ([0.0, 0.0, 40.0], [5.0, 5.0, 21.3]):  # goals covering the arena leave no room for a start
        with pytest.raises(ValueError) as e:
            env.reset(seed=0, options={"goal": goal})
        msg = str(e.value)
        assert "option 'goal'" in msg and "covers the whole arena" in msg
        assert "option 'state'" not in msg and "initial position" not in msg
    env.reset(seed=0, options={"goal": [5.0, 5.0, 21.0]})  # (-10, -10) lies 21.21 from the centre: it stays free
    with pytest.raises(ValueError) as e:  # obstacles covering the given start in every draw
        Dubins4DGuardedEnv(obstacle_min_rad=30.0, obstacle_max_rad=40.0).reset(
            seed=0, options={"state": STATE_AT_ORIGIN}
        )
    assert "option 'state'" in str(e.value) and "'obstacles' explicitly" in str(e.value)


def test_maze_state_option_gets_a_maze_clear_of_it():
    from rmm_envs.systems.maze.env import Dubins3DMazeEnv
    from rmm_envs.systems.maze.mazes import generate_maze

    env = Dubins3DMazeEnv()
    state = [375.0, 437.5, 0.0]  # on the side shared by two cells: a wall in some mazes, not in others
    for seed in range(20):  # seeds 9 and 19 draw a wall there first
        _, info = env.reset(seed=seed, options={"state": state})
        assert info["state"].tolist() == state and not env.scene.maze.state_failed(np.array([state[:2]]))[0]
    walled = generate_maze(np.random.default_rng(0))
    bad = next(
        p for p in ([x, 437.5] for x in np.arange(250.0, 2500.0, 125.0)) if walled.state_failed(np.array([p]))[0]
    )
    with pytest.raises(ValueError, match="inside a wall of option 'maze'"):
        env.reset(seed=0, options={"state": [*bad, 0.0], "maze": walled})


def test_quadrotor_state_option_gets_a_room_clear_of_it():
    from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv

    env = QuadrotorRoomEnv()
    try:
        state = np.array([1.0, 1.0, 0.5, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0])
        for seed in range(9):  # seeds 1, 2, 6 and 8 draw a room that touches it first
            _, info = env.reset(seed=seed, options={"state": state})
            np.testing.assert_allclose(info["state"][:3], state[:3])
            assert not env.in_contact()
    finally:
        env.close()


# ---------------------------------------------------------------------- parameters that disable what they configure
@pytest.mark.parametrize(
    "kwargs, name",
    [
        ({"max_episode_sim_time": math.inf}, "max_episode_sim_time"),
        ({"goal_max_rad": math.inf}, "goal radii"),
        ({"obstacle_max_rad": math.inf}, "obstacle radii"),
        ({"n_obstacles": math.inf}, "n_obstacles"),
        ({"n_rays": math.inf}, "n_rays"),
    ],
)
def test_dubins4d_non_finite_parameters_refused(kwargs, name):
    with pytest.raises(ValueError, match=f"{name} must be"):
        Dubins4DGuardedEnv(**kwargs)
    with pytest.raises(ValueError, match=f"{name} must be"):
        gym.make("Dubins4DParallel-v0", **kwargs)


def test_maze_and_quadrotor_non_finite_parameters_refused():
    from rmm_envs.systems.maze.env import Dubins3DMazeEnv
    from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv

    with pytest.raises(ValueError, match="speed must be a finite number"):
        Dubins3DMazeEnv(speed=math.inf)
    for steps in (math.inf, math.nan, "100", 2.5, 0):  # inf used to raise a raw OverflowError
        with pytest.raises(ValueError, match="max_episode_steps must be an integer >= 1"):
            Dubins3DMazeEnv(max_episode_steps=steps)
    assert Dubins3DMazeEnv(max_episode_steps=np.int64(5)).max_episode_steps == 5
    with pytest.raises(ValueError, match="max_episode_time must be a finite"):
        QuadrotorRoomEnv(max_episode_time=math.inf)
    with pytest.raises(ValueError, match="damping must be finite"):
        QuadrotorRoomEnv(linear_damping=math.inf)


# ---------------------------------------------------------------------- order independence
def _episode_bits(env, seed):
    obs, info = env.reset(seed=seed)
    trace = [obs.tobytes()]
    while True:
        obs, r, te, tr, info = env.step({"active_ctrl": 0, "turnrate_ctrl": np.zeros(1), "accel_ctrl": np.zeros(1)})
        trace += [obs.tobytes(), info["state"].tobytes(), info["control"].tobytes()]
        if te or tr:
            stats = info["episode_stats"]
            return trace, {k: struct.pack("d", v) if isinstance(v, float) else v for k, v in stats.items()}


def test_episode_floats_do_not_depend_on_the_episodes_run_before():
    seeds = [3, 8, 14, 21]
    env = Dubins4DGuardedEnv(max_episode_sim_time=30.0, clock="fixed:1")
    forward = {s: _episode_bits(env, s) for s in seeds}
    backward = {s: _episode_bits(env, s) for s in reversed(seeds)}
    fresh = {s: _episode_bits(Dubins4DGuardedEnv(max_episode_sim_time=30.0, clock="fixed:1"), s) for s in seeds}
    for s in seeds:
        assert forward[s] == backward[s] == fresh[s], f"episode seed {s} changed with the order"


def test_check_env_finds_the_parallel_env_deterministic():
    from gymnasium.utils.env_checker import check_env

    from rmm_envs.wrappers.nonblocking import NonBlockingStepping

    env = NonBlockingStepping(Dubins4DGuardedEnv(), clock="fixed:2")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env, skip_render_check=True)
    msgs = [str(w.message) for w in caught]
    assert not [m for m in msgs if "not equal" in m or "determinis" in m.lower()], msgs


# columns that are measurements of real time (the guardian's own wall-clock decision time, the
# episode's wall time and finishing time) legitimately differ between runs; every other stored
# value must be identical bit for bit
_TIMING_COLUMNS = {"decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time", "finished"}


def _stored(db):
    con = sqlite3.connect(db)
    try:
        cols = [r[1] for r in con.execute("PRAGMA table_info(episodes)") if r[1] not in _TIMING_COLUMNS | {"run_key"}]
        rows = con.execute(f"SELECT {', '.join(cols)} FROM episodes ORDER BY agent, episode").fetchall()
    finally:
        con.close()
    return cols, [tuple(struct.pack("d", v) if isinstance(v, float) else v for v in r) for r in rows]


@pytest.mark.heavy
def test_bench_rows_bit_identical_with_1_and_2_workers(tmp_path):
    from rmm_bench.cli import main as bench

    common = [
        "--agent",
        "random",
        "--episodes",
        "4",
        "--clock",
        "fixed:1",
        "--no-progress",
        "--env",
        "Dubins4DParallel-v0",
        "--agent-opt",
        "random.p_active=0.3",
        "--no-figure",
    ]
    assert bench([*common, "--workers", "1", "--out", str(tmp_path / "w1")]) == 0
    assert bench([*common, "--workers", "2", "--out", str(tmp_path / "w2")]) == 0
    cols, one = _stored(tmp_path / "w1" / "results.db")
    _, two = _stored(tmp_path / "w2" / "results.db")
    assert "final_speed" in cols and "sim_time" in cols and len(one) == 4
    for a, b in zip(one, two, strict=True):  # both runs finished (status 0): the same 4 episodes
        assert a == b, {c: (x, y) for c, x, y in zip(cols, a, b, strict=True) if x != y}  # one value per column


@pytest.mark.parametrize(
    "params, name",
    [
        ({"lambda_v": math.inf}, "lambda_v"),
        ({"gamma_vmax": math.nan}, "gamma_vmax"),
        ({"p_theta": 0.0}, "p_theta"),
        ({"speed_gain": 1.0}, "speed_gain"),
    ],
)
def test_driver_parameters_that_disable_a_constraint_refused(params, name):
    with pytest.raises(ValueError, match=name):
        Dubins4DGuardedEnv(driver_params=params)


def test_datagen_negative_seed_names_the_flag(tmp_path, capsys):
    assert (
        datagen_main(
            [
                "--seed",
                "-1",
                "--configs",
                "1",
                "--samples-per-config",
                "2",
                "--branches",
                "2",
                "--workers",
                "1",
                "--out",
                str(tmp_path / "s"),
                "--no-progress",
            ]
        )
        == 2
    )
    assert "--seed" in capsys.readouterr().err
