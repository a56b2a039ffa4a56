"""A dataset directory is read only when it is whole and what it says it is (``rmm_envs/risk/dataset.py``,
``rmm_envs/risk/datagen.py``).

``load_dataset`` reads exactly the shards the metadata implies, each matching the manifest's
checksum: a shard missing from the disk or from the manifest, or one the manifest lists beyond
those, is refused with a message naming it; a stray file nobody listed is never read.  A rerun
of ``rmm-datagen`` into a directory made with other parameters (any of them: env id, env
arguments, sizes, seed, estimator) is refused naming the parameter, before a shard is touched."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rmm_envs.risk.datagen import DatagenConfig, generate
from rmm_envs.risk.dataset import identity, load_dataset

CFG = dict(configs=3, samples_per_config=4, branches=4, depth=1, configs_per_shard=1, seed=7)
SHARDS = [f"shard-{i:05d}.parquet" for i in range(3)]


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("ds") / "d"
    generate(DatagenConfig(**CFG), out, workers=1, progress=False)
    return out


def _copy(made: Path, tmp: Path) -> Path:
    d = tmp / "copy"
    if d.exists():
        shutil.rmtree(d)
    shutil.copytree(made, d)
    return d


def _edit_manifest(d: Path, edit) -> None:
    m = json.loads((d / "manifest.json").read_text())
    edit(m["shards"])
    (d / "manifest.json").write_text(json.dumps(m))


def test_the_whole_dataset_loads(made):
    import pyarrow as pa
    import pyarrow.parquet as pq

    ds = load_dataset(made)
    assert len(ds) == 12 and ds.config_id.tolist() == [0] * 4 + [1] * 4 + [2] * 4
    t = pa.concat_tables([pq.read_table(made / name) for name in SHARDS])  # every field is the files' column
    for name in ("risk", "min_risk_ctrl_dur", "n_leaves", "config_id"):
        np.testing.assert_array_equal(getattr(ds, name), t[name].to_numpy())
    for name, width in (("obs", 17), ("state", 4), ("min_risk_ctrl", 2)):
        np.testing.assert_array_equal(getattr(ds, name), np.array(t[name].to_pylist()).reshape(12, width))
    assert ds.obs.dtype == np.float32 and ds.candidate_risk is None
    assert sorted(p.name for p in made.glob("shard-*")) == SHARDS  # the checksum files are folded in


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(gone=st.sets(st.sampled_from(SHARDS), min_size=1))
def test_a_shard_missing_from_the_disk_is_refused_by_name(made, tmp_path, gone):
    d = _copy(made, tmp_path)
    for name in gone:
        (d / name).unlink()
    with pytest.raises(ValueError, match=rf"{min(gone)} is listed in the manifest but missing: rerun `rmm-datagen"):
        load_dataset(d)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(gone=st.sets(st.sampled_from(SHARDS), min_size=1))
def test_a_shard_missing_from_the_manifest_is_refused_by_name(made, tmp_path, gone):
    """Even with its file on the disk: the manifest, not the directory listing, says what the dataset is."""
    d = _copy(made, tmp_path)
    _edit_manifest(d, lambda shards: [shards.pop(n) for n in gone])
    with pytest.raises(ValueError, match=r"does not list the shards metadata.json implies") as e:
        load_dataset(d)
    assert f"missing {sorted(gone)[:3]}" in str(e.value) and "unexpected []" in str(e.value)


def test_a_shard_the_manifest_lists_beyond_the_metadata_is_refused_by_name(made, tmp_path):
    d = _copy(made, tmp_path)
    shutil.copy(d / SHARDS[2], d / "shard-00003.parquet")
    _edit_manifest(d, lambda shards: shards.update({"shard-00003.parquet": shards[SHARDS[2]]}))
    with pytest.raises(ValueError, match=r"missing \[\], unexpected \['shard-00003.parquet'\]"):
        load_dataset(d)


def test_a_stray_shard_file_is_never_read(made, tmp_path):
    """A shard file in the directory that the manifest does not list (left by another run) is not
    part of the dataset: the rows are exactly the listed shards'."""
    d = _copy(made, tmp_path)
    shutil.copy(d / SHARDS[0], d / "shard-00003.parquet")
    shutil.copy(d / SHARDS[1], d / "shard-00099.parquet")
    a, b = load_dataset(made), load_dataset(d)
    assert len(b) == len(a) == 12
    np.testing.assert_array_equal(b.config_id, a.config_id)
    np.testing.assert_array_equal(b.risk, a.risk)
    assert b.sha256 == a.sha256


def test_metadata_implying_other_shards_is_refused(made, tmp_path):
    d = _copy(made, tmp_path)
    meta = json.loads((d / "metadata.json").read_text())
    (d / "metadata.json").write_text(json.dumps(meta | {"configs": 4}))
    with pytest.raises(ValueError, match=r"missing \['shard-00003.parquet'\]"):
        load_dataset(d)


# ------------------------------------------------------------------ other parameters are refused by name
def test_identity_is_every_parameter_that_makes_the_data():
    meta = {
        "format": "rmm-dataset",
        "format_version": 1,
        "env_id": "E",
        "env_kwargs": {"a": 1},
        "configs": 3,
        "samples_per_config": 4,
        "seed": 7,
        "configs_per_shard": 1,
        "estimator": {"branches": 4},
        "package_version": "1",
        "created": "now",
        "obs_dim": 17,
    }
    base = identity(meta)
    for key in (
        "format",
        "format_version",
        "env_id",
        "env_kwargs",
        "configs",
        "samples_per_config",
        "seed",
        "configs_per_shard",
        "estimator",
    ):
        assert identity(meta | {key: "other"}) != base, key
    # what records the run rather than defines the data is not part of it
    assert identity(meta | {"package_version": "2", "created": "later"}) == base


@pytest.mark.parametrize(
    "key, value",
    [
        ("env_kwargs", {"n_obstacles": 4}),
        ("env_id", "Dubins4DMapGuarded-v0"),
        ("seed", 8),
        ("configs", 2),
        ("samples_per_config", 5),
        ("configs_per_shard", 3),
        ("estimator", {"branches": 5}),
    ],
)
def test_a_rerun_into_a_dataset_made_with_other_parameters_is_refused_by_name(made, tmp_path, key, value):
    """The existing ``metadata.json`` records other parameters than the rerun's: refused, naming the
    parameter with both values, and no file of the dataset changes."""
    d = _copy(made, tmp_path)
    meta = json.loads((d / "metadata.json").read_text())
    recorded = meta[key] | value if isinstance(value, dict) and key == "estimator" else value
    (d / "metadata.json").write_text(json.dumps(meta | {key: recorded}))
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    with pytest.raises(ValueError, match="holds a dataset made with other parameters") as e:
        generate(DatagenConfig(**CFG), d, workers=1, progress=False)
    assert f"'{key}': ({recorded!r}, {meta[key]!r})" in str(e.value)
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before


def test_other_env_arguments_are_refused_before_any_work(made, tmp_path):
    """The same command with other ``--env-kwargs``: refused, naming ``env_kwargs``."""
    d = _copy(made, tmp_path)
    with pytest.raises(ValueError, match=r"'env_kwargs': \(\{\}, \{'n_obstacles': 4\}\)"):
        generate(DatagenConfig(**CFG, env_kwargs={"n_obstacles": 4}), d, workers=1, progress=False)


# ------------------------------------------------------------------ the files' helpers, by hand
def test_rerun_command_names_every_parameter_and_quotes_the_folder():
    from rmm_envs.risk.dataset import rerun_command

    meta = {
        "env_id": "Dubins3DMaze-v0",
        "configs": 5,
        "samples_per_config": 6,
        "seed": 2,
        "configs_per_shard": 3,
        "estimator": {
            "branches": 7,
            "depth": 2,
            "horizon": 1.5,
            "n_steps": 4,
            "metric": "cvar",
            "alpha": 0.1,
            "leaf": "heuristic",
            "policy": "uniform",
        },
        "env_kwargs": {"maze_kind": "mixed", "a": 1},
    }
    assert rerun_command(meta, "/data/my set") == (
        "rmm-datagen --env Dubins3DMaze-v0 --configs 5 --samples-per-config 6 --seed 2 --configs-per-shard 3 "
        "--branches 7 --depth 2 --horizon 1.5 --n-steps 4 --metric cvar --alpha 0.1 --leaf heuristic "
        """--env-opt a=1 --env-opt 'maze_kind="mixed"' --out '/data/my set'"""
    )
    # parameters that are not set are left out; no estimator or env arguments at all
    meta = {
        "env_id": "E",
        "configs": 1,
        "samples_per_config": 2,
        "seed": 0,
        "configs_per_shard": 1,
        "estimator": {"branches": 3, "alpha": None},
        "env_kwargs": {},
    }
    assert rerun_command(meta, "out") == (
        "rmm-datagen --env E --configs 1 --samples-per-config 2 --seed 0 --configs-per-shard 1 --branches 3 --out out"
    )
    assert rerun_command({}, "o") == (
        "rmm-datagen --env None --configs None --samples-per-config None --seed None --configs-per-shard None --out o"
    )


def test_checksums_are_written_beside_a_shard_and_read_back_only_when_well_formed(tmp_path):
    import hashlib

    import pyarrow as pa

    from rmm_envs.risk.dataset import checksum_path, recorded_checksum, sha256_file, shard_ok, shard_path, write_table

    p = shard_path(tmp_path, 3)
    assert p.name == "shard-00003.parquet" and checksum_path(p).name == "shard-00003.sha256"
    write_table(p, pa.table({"x": [1, 2, 3]}))
    digest = hashlib.sha256(p.read_bytes()).hexdigest()
    assert checksum_path(p).read_text() == f"{digest}  shard-00003.parquet\n"  # sha256sum -c format
    assert recorded_checksum(p) == digest == sha256_file(p)
    import pyarrow.parquet as pq

    assert pq.ParquetFile(p).metadata.row_group(0).column(0).compression == "ZSTD"
    assert shard_ok(p, 3) and not shard_ok(p, 4) and not shard_ok(tmp_path / "none.parquet", 0)
    assert not list(tmp_path.glob(".*.tmp"))  # written through a temporary file, renamed into place
    for bad in (digest[:63], digest.upper(), "g" * 64, "X" * 64, "", "\xff"):
        checksum_path(p).write_text(bad)
        assert recorded_checksum(p) is None, bad
    checksum_path(p).write_bytes(b"\xff\xfe")
    assert recorded_checksum(p) is None
    checksum_path(p).unlink()
    assert recorded_checksum(p) is None


def test_an_unreadable_manifest_is_a_problem_named_not_a_crash(tmp_path):
    from rmm_envs.risk.dataset import read_manifest_shards

    assert read_manifest_shards(tmp_path) == ({}, None)
    (tmp_path / "manifest.json").write_text(json.dumps({"shards": {"shard-00000.parquet": "ab", 7: 1}}))
    assert read_manifest_shards(tmp_path) == ({"shard-00000.parquet": "ab", "7": "1"}, None)
    (tmp_path / "manifest.json").write_text('{"shards": []}')
    assert read_manifest_shards(tmp_path)[1] == (
        f"{tmp_path / 'manifest.json'} is unreadable (TypeError: 'shards' is not "
        "a mapping); its checksums cannot be used"
    )
    for text, kind in (("{", "JSONDecodeError"), ('{"shards": []}', "TypeError"), ("{}", "KeyError")):
        (tmp_path / "manifest.json").write_text(text)
        shards, problem = read_manifest_shards(tmp_path)
        assert shards == {} and problem.startswith(f"{tmp_path / 'manifest.json'} is unreadable ({kind}")
        assert problem.endswith("its checksums cannot be used")


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda d: (d / "manifest.json").unlink(), r"is incomplete \(no manifest.json\): rerun `rmm-datagen"),
        (lambda d: (d / "manifest.json").write_text("[1]"), r"manifest.json is unreadable \(TypeError"),
        (
            lambda d: (d / "manifest.json").write_text('{"shards": {}}'),
            r"manifest.json is unreadable \(KeyError: 'dataset_sha256'\)",
        ),
        (
            lambda d: (d / "metadata.json").write_text("[]"),
            r"metadata.json is unreadable or not valid JSON \(not a JSON object\)",
        ),
        (
            lambda d: (d / "metadata.json").write_text(
                json.dumps(json.loads((d / "metadata.json").read_text()) | {"format_version": 2})
            ),
            r"metadata.json: expected format rmm-dataset v1, got rmm-dataset v2",
        ),
        (
            lambda d: (d / "metadata.json").write_text(
                json.dumps(json.loads((d / "metadata.json").read_text()) | {"obs_dim": 5})
            ),
            r"observations have 17 features, metadata says 5",
        ),
    ],
)
def test_each_damaged_file_is_refused_naming_it(made, tmp_path, damage, message):
    d = _copy(made, tmp_path)
    damage(d)
    with pytest.raises(ValueError, match=message):
        load_dataset(d)


def test_a_shard_that_matches_its_checksum_but_is_not_parquet_is_refused(made, tmp_path):
    import hashlib

    d = _copy(made, tmp_path)
    (d / SHARDS[1]).write_bytes(b"PAR1 not really")
    _edit_manifest(d, lambda shards: shards.update({SHARDS[1]: hashlib.sha256(b"PAR1 not really").hexdigest()}))
    with pytest.raises(ValueError, match=rf"{SHARDS[1]} cannot be read \("):
        load_dataset(d)


def test_metadata_without_sizes_skips_the_shard_list_check(made, tmp_path):
    """An older metadata file without ``configs_per_shard``: the shards are those the manifest lists."""
    d = _copy(made, tmp_path)
    meta = json.loads((d / "metadata.json").read_text())
    del meta["configs_per_shard"]
    (d / "metadata.json").write_text(json.dumps(meta))
    assert len(load_dataset(d)) == 12
    _edit_manifest(d, lambda shards: shards.clear())
    with pytest.raises(ValueError, match=r"holds no shards$"):
        load_dataset(d)


def test_more_than_three_missing_shards_are_listed_three_and_an_ellipsis(made, tmp_path):
    d = _copy(made, tmp_path)
    meta = json.loads((d / "metadata.json").read_text())
    (d / "metadata.json").write_text(json.dumps(meta | {"configs": 7}))  # 7 shards of 1 config: 4 missing
    with pytest.raises(
        ValueError,
        match=re.escape(
            "(missing ['shard-00003.parquet', 'shard-00004.parquet', 'shard-00005.parquet']..., unexpected [])"
        ),
    ):
        load_dataset(d)


@pytest.mark.parametrize("column", ["obs", "state", "min_risk_ctrl"])
def test_a_column_that_is_not_a_fixed_size_list_is_named(made, tmp_path, column):
    import hashlib

    import pyarrow as pa
    import pyarrow.parquet as pq

    d = _copy(made, tmp_path)
    for name in SHARDS:  # every shard alike (shards of different schemas are refused earlier)
        t = pq.read_table(d / name)
        t = t.set_column(t.column_names.index(column), column, t[column].cast(pa.list_(t[column].type.value_type)))
        pq.write_table(t, d / name)
        _edit_manifest(
            d, lambda shards, name=name: shards.update({name: hashlib.sha256((d / name).read_bytes()).hexdigest()})
        )
    with pytest.raises(ValueError) as e:
        load_dataset(d)
    assert str(e.value).startswith(f"{d}: column '{column}' should be a fixed-size list, got list<")


def test_candidate_labels_are_read_back(tmp_path):
    """A dataset made with ``candidates``: one risk per candidate control and row."""
    cands = [[-0.25, -0.5], [0.25, 0.5], [0.0, 0.0]]
    generate(
        DatagenConfig(**(CFG | {"configs": 1, "samples_per_config": 3}), candidates=cands),
        tmp_path / "c",
        workers=1,
        progress=False,
    )
    ds = load_dataset(tmp_path / "c")
    assert ds.candidate_risk.shape == (3, 3) and np.all((ds.candidate_risk >= 0) & (ds.candidate_risk <= 1))
    assert load_dataset(tmp_path / "c").meta["estimator"]["candidates"] == cands
    import hashlib

    import pyarrow as pa
    import pyarrow.parquet as pq

    d, name = tmp_path / "c", SHARDS[0]
    t = pq.read_table(d / name)
    col = t["candidate_risk"]
    pq.write_table(
        t.set_column(t.column_names.index("candidate_risk"), "candidate_risk", col.cast(pa.list_(col.type.value_type))),
        d / name,
    )
    _edit_manifest(d, lambda shards: shards.update({name: hashlib.sha256((d / name).read_bytes()).hexdigest()}))
    with pytest.raises(ValueError, match=rf"^{re.escape(str(d))}: column 'candidate_risk' should be a fixed-size list"):
        load_dataset(d)


def test_shards_of_different_schemas_are_refused_in_one_line(made, tmp_path):
    """Shards whose checksums match but whose columns differ (written by different versions):
    one line naming the folder and the repair, not pyarrow's schema dump."""
    import hashlib

    import pyarrow as pa
    import pyarrow.parquet as pq

    d = _copy(made, tmp_path)
    t = pq.read_table(d / SHARDS[1])
    pq.write_table(
        t.set_column(t.column_names.index("obs"), "obs", t["obs"].cast(pa.list_(pa.float32()))), d / SHARDS[1]
    )
    _edit_manifest(
        d, lambda shards: shards.update({SHARDS[1]: hashlib.sha256((d / SHARDS[1]).read_bytes()).hexdigest()})
    )
    with pytest.raises(ValueError) as e:
        load_dataset(d)
    assert "\n" not in str(e.value)
    assert str(e.value).startswith(f"{d}: the shards do not share one schema (Schema at index 1 was different:")
    assert "rerun `rmm-datagen" in str(e.value)
