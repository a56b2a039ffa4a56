import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset, main

SMALL = dict(configs=6, samples_per_config=10, branches=6, depth=2, configs_per_shard=2, seed=3)


def small(**kw):
    return DatagenConfig(**(SMALL | kw))


def test_dataset_contents(tmp_path):
    man = generate(small(), tmp_path / "d", workers=1, progress=False)
    ds = load_dataset(tmp_path / "d")
    assert len(ds) == 60 == man["n_rows"]
    assert ds.obs.shape == (60, 17) and ds.obs.dtype == np.float32
    assert ds.state.shape == (60, 4) and ds.min_risk_ctrl.shape == (60, 2)
    assert np.all((ds.risk >= 0) & (ds.risk <= 1))
    # grouped by configuration, each configuration whole
    assert ds.config_id.tolist() == sorted(ds.config_id.tolist())
    assert np.bincount(ds.config_id).tolist() == [10] * 6
    # the sim-time feature is spread over the episode, not stuck at 0 as in the original
    assert ds.obs[:, 0].min() >= 0 and ds.obs[:, 0].max() <= 100 and ds.obs[:, 0].std() > 10
    # observations are consistent with the stored states
    np.testing.assert_allclose(ds.obs[:, 4], ds.state[:, 3], rtol=1e-6)
    meta = json.loads((tmp_path / "d" / "metadata.json").read_text())
    assert meta["estimator"]["branches"] == 6 and meta["seed"] == 3 and "package_version" in meta


def test_to_pandas_round_trips_every_field(tmp_path):
    generate(small(configs=2, samples_per_config=5), tmp_path / "d", workers=1, progress=False)
    ds = load_dataset(tmp_path / "d")
    df = ds.to_pandas()
    assert len(df) == 10
    assert list(df.columns[:4]) == ["config_id", "risk", "min_risk_ctrl_dur", "n_leaves"]
    assert [c for c in df.columns if c.startswith("obs_")] == [f"obs_{j}" for j in range(17)]
    np.testing.assert_array_equal(df[[f"obs_{j}" for j in range(17)]].to_numpy(), ds.obs)
    assert df["obs_3"].dtype == np.float32 and df["state_0"].dtype == np.float64
    np.testing.assert_array_equal(df[["state_0", "state_1", "state_2", "state_3"]].to_numpy(), ds.state)
    np.testing.assert_array_equal(df[["min_risk_ctrl_0", "min_risk_ctrl_1"]].to_numpy(), ds.min_risk_ctrl)
    for name in ("config_id", "risk", "min_risk_ctrl_dur", "n_leaves"):
        np.testing.assert_array_equal(df[name].to_numpy(), getattr(ds, name))
    assert df.attrs["sha256"] == ds.sha256 and df.attrs["meta"]["seed"] == 3
    # a groupby works as a user would write it: the mean risk per configuration
    np.testing.assert_allclose(
        df.groupby("config_id")["risk"].mean().to_numpy(), [ds.risk[ds.config_id == c].mean() for c in (0, 1)]
    )
    lists = ds.to_pandas(vectors="lists")
    assert list(lists.columns) == [
        "config_id",
        "risk",
        "min_risk_ctrl_dur",
        "n_leaves",
        "obs",
        "state",
        "min_risk_ctrl",
    ]
    np.testing.assert_array_equal(np.stack(lists["obs"].to_list()), ds.obs)
    np.testing.assert_array_equal(np.stack(lists["state"].to_list()), ds.state)
    with pytest.raises(ValueError, match="vectors must be 'columns' or 'lists', got 'wide'"):
        ds.to_pandas(vectors="wide")


def test_same_seed_same_data_whatever_the_worker_count(tmp_path):
    a = generate(small(), tmp_path / "a", workers=1, progress=False)
    b = generate(small(), tmp_path / "b", workers=2, progress=False)
    assert a["dataset_sha256"] == b["dataset_sha256"]
    da, db = load_dataset(tmp_path / "a"), load_dataset(tmp_path / "b")
    np.testing.assert_array_equal(da.risk, db.risk)
    c = generate(small(seed=4), tmp_path / "c", workers=1, progress=False)
    assert c["dataset_sha256"] != a["dataset_sha256"]


def test_rerun_is_a_no_op_and_other_parameters_are_refused(tmp_path):
    generate(small(), tmp_path / "d", workers=1, progress=False)
    again = generate(small(), tmp_path / "d", workers=1, progress=False)
    assert again["last_run"]["new_rows"] == 0
    with pytest.raises(ValueError, match="other parameters"):
        generate(small(branches=7), tmp_path / "d", workers=1, progress=False)


@pytest.mark.slow  # rmm-bench's kill -9 drill runs in the default suite; this one costs three commands
def test_resume_after_kill_minus_nine(tmp_path):
    out = tmp_path / "k"
    # a small tree (8 branches, not the default 32): the labels' cost is not what is tested
    args = [
        sys.executable,
        "-m",
        "rmm_envs.risk.datagen",
        "--configs",
        "24",
        "--samples-per-config",
        "40",
        "--branches",
        "8",
        "--configs-per-shard",
        "1",
        "--workers",
        "1",
        "--seed",
        "5",
        "--out",
        str(out),
        "--no-progress",
    ]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    while time.time() < deadline and len(list(out.glob("shard-*.parquet"))) < 3:
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    partial = len(list(out.glob("shard-*.parquet")))
    assert 3 <= partial < 24, "the run should have been killed midway"
    assert not (out / "manifest.json").exists()
    with pytest.raises(ValueError, match="incomplete"):
        load_dataset(out)
    assert subprocess.run(args, capture_output=True).returncode == 0
    resumed = load_dataset(out)
    pairs = set(zip(resumed.config_id.tolist(), resumed.obs[:, 0].tolist(), strict=True))  # one pair per row
    assert len(resumed) == 24 * 40 == len(pairs)  # nothing lost, nothing duplicated
    generate(
        DatagenConfig(configs=24, samples_per_config=40, branches=8, configs_per_shard=1, seed=5),
        tmp_path / "ref",
        workers=2,
        progress=False,
    )
    np.testing.assert_array_equal(load_dataset(tmp_path / "ref").risk, resumed.risk)


def test_a_run_cut_short_resumes_with_exactly_the_missing_shards(tmp_path):
    """What a kill -9 leaves (some shards with their checksums, no manifest), made in-process:
    the rerun computes only the missing shards, and the data equal an uninterrupted run's.
    The kill -9 itself is a slow drill above."""
    from rmm_envs.risk.dataset import checksum_path, shard_path

    out = tmp_path / "d"
    man = generate(small(), out, workers=1, progress=False)
    ref = load_dataset(out)
    (out / "manifest.json").unlink()
    first = shard_path(out, 0)  # written, with the checksum file a shard gets until the manifest holds it
    checksum_path(first).write_text(f"{man['shards'][first.name]}  {first.name}\n")
    for s in (1, 2):  # shards 1 and 2 of 0-2 never written
        shard_path(out, s).unlink()
    with pytest.raises(ValueError, match="incomplete"):
        load_dataset(out)
    man = generate(small(), out, workers=1, progress=False)
    assert man["last_run"]["new_rows"] == 2 * 2 * 10  # two shards of two configurations of 10 samples
    assert man["last_run"]["regenerated"] == []  # shard 0 verified and kept
    resumed = load_dataset(out)
    np.testing.assert_array_equal(resumed.risk, ref.risk)
    np.testing.assert_array_equal(resumed.obs, ref.obs)


def test_half_written_shard_is_redone(tmp_path):
    out = tmp_path / "d"
    generate(small(), out, workers=1, progress=False)
    ref = load_dataset(out).risk
    shard = out / "shard-00001.parquet"
    shard.write_bytes(shard.read_bytes()[:100])  # a truncated file
    (out / ".shard-00002.parquet.123.tmp").write_bytes(b"junk")
    with pytest.raises(ValueError, match="checksum"):
        load_dataset(out)
    man = generate(small(), out, workers=1, progress=False)
    assert man["last_run"]["new_rows"] == 20
    assert not list(out.glob(".shard-*"))
    np.testing.assert_array_equal(load_dataset(out).risk, ref)


@pytest.mark.slow  # a Ray cluster of its own (25-35 s), like the other Ray drills (tests/test_faults.py, test_bench_imports.py)
def test_ray_backend_gives_the_same_data(tmp_path):
    try:  # ray is in the test extra: a missing install must fail, not skip
        import ray
    except ImportError as e:
        raise ImportError("this test needs ray, part of the test extra: pip install -e '.[test]'") from e
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        a = generate(small(), tmp_path / "ray", backend="ray", progress=False)
    finally:
        ray.shutdown()
    b = generate(small(), tmp_path / "local", workers=1, progress=False)
    assert a["dataset_sha256"] == b["dataset_sha256"]


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"configs": 0}, "configs"),
        ({"depth": -1}, "depth"),
        ({"horizon": 0.0}, "horizon"),
        ({"n_steps": 1}, "n_steps"),
        ({"metric": "cvar", "alpha": 1.5}, "alpha"),
        ({"env_id": "Nope-v0"}, "is not a registered Gymnasium env"),
        ({"branches": 0}, "branches"),
    ],
)
def test_bad_configuration(tmp_path, kw, match):
    with pytest.raises(ValueError, match=match):
        generate(small(**kw), tmp_path / "x", workers=1, progress=False)


def test_cli_errors_and_success(tmp_path, capsys):
    assert (
        main(
            [
                "--out",
                str(tmp_path / "c"),
                "--configs",
                "2",
                "--samples-per-config",
                "4",
                "--branches",
                "4",
                "--workers",
                "1",
                "--no-progress",
            ]
        )
        == 0
    )
    assert "8 labelled samples" in capsys.readouterr().out
    assert main(["--out", str(tmp_path / "c"), "--configs", "3", "--samples-per-config", "4", "--no-progress"]) == 2
    assert "other parameters" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["--out", str(tmp_path / "e"), "--metric", "median"])


def test_load_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="metadata.json"):
        load_dataset(tmp_path)
    (tmp_path / "metadata.json").write_text("{not json")
    with pytest.raises(ValueError, match="JSON"):
        load_dataset(tmp_path)
    (tmp_path / "metadata.json").write_text(json.dumps({"format": "other"}))
    with pytest.raises(ValueError, match="format"):
        load_dataset(tmp_path)


def test_datagen_reaches_any_env_through_the_labelled_env_protocol_only(tmp_path, capsys):
    """An env registered under another id (so no id prefix can say what it is) gives the very
    same dataset as the package's own id; an env without the protocol is refused by name."""
    import gymnasium as gym

    if "ThirdPartyMaze-v0" not in gym.registry:
        gym.register(id="ThirdPartyMaze-v0", entry_point="rmm_envs.systems.maze.env:Dubins3DMazeEnv")
    tiny = dict(configs=1, samples_per_config=4, branches=2, depth=1, configs_per_shard=1, seed=5)
    ours = generate(DatagenConfig(env_id="Dubins3DMaze-v0", **tiny), tmp_path / "ours", workers=1, progress=False)
    theirs = generate(DatagenConfig(env_id="ThirdPartyMaze-v0", **tiny), tmp_path / "theirs", workers=1, progress=False)
    assert ours["dataset_sha256"] == theirs["dataset_sha256"]
    meta = json.loads((tmp_path / "theirs" / "metadata.json").read_text())
    assert (meta["obs_dim"], meta["state_dim"], meta["control_dim"], meta["obs_time_feature"]) == (8, 3, 1, None)
    generate(DatagenConfig(**tiny), tmp_path / "d4", workers=1, progress=False)
    d4 = json.loads((tmp_path / "d4" / "metadata.json").read_text())
    assert d4["obs_time_feature"] == "uniform over [0, max_episode_sim_time]" and d4["control_dim"] == 2
    with pytest.raises(
        TypeError,
        match=r"MountainCar-v0 \(MountainCarEnv\) is not a LabelledEnv.*risk_scene is missing"
        r".*no risk adapter serves it either",
    ):
        generate(DatagenConfig(env_id="MountainCar-v0", **tiny), tmp_path / "mc", workers=1, progress=False)
    assert main(["--env", "MountainCar-v0", "--out", str(tmp_path / "mc2"), "--no-progress"]) == 2
    assert "is not a LabelledEnv" in capsys.readouterr().err and not (tmp_path / "mc2").exists()
