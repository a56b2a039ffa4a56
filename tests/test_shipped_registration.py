"""The shipped LRMM models are registered for their systems in one text file beside the models
(guardians/lrmm/models/shipped.toml), not in a table of system names in Python."""

from __future__ import annotations

import pytest

from rmm_envs.catalog import SYSTEMS
from rmm_guardians.lrmm.shipped import (
    REGISTRATION,
    SHIPPED,
    SHIPPED_BY_SYSTEM,
    _read_registration,
    calibrated,
    models_dir,
)


def test_every_registered_model_file_is_shipped_and_every_system_is_known():
    names = {s.name for s in SYSTEMS}
    assert set(SHIPPED_BY_SYSTEM) <= names
    for kinds in SHIPPED_BY_SYSTEM.values():
        for ship in kinds.values():
            for file in ship.files.values():
                assert (models_dir() / file).is_file(), file


def test_the_registration_gives_each_env_id_its_files_and_inputs():
    assert SHIPPED["Dubins4DGuarded-v0"].files == {"paper": "dubins4d.npz", "act": "dubins4d_act.npz"}
    assert SHIPPED["Dubins4DMapParallel-v0"].files == SHIPPED["Dubins4DGuarded-v0"].files
    assert SHIPPED["Dubins3DMazeParallel-v0"].inputs == "rays"
    assert SHIPPED["Dubins3DMaze-v0"].files == {"paper": "dubins3d_maze.npz"}
    assert SHIPPED["QuadrotorRoomGuarded-v0"].files == {"act": "quadrotor_cmd_act.npz", "risk": "quadrotor_cmd.npz"}
    assert SHIPPED["CartPoleParallel-v0"].inputs is None


@pytest.mark.parametrize(
    "text, words",
    [
        ('format = "other"\nversion = 1\n', ["format = 'rmm-lrmm-shipped'", "'other'"]),
        ('format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.vector]\nfiles = {act = "a.npz"}\n', ["'vector'"]),
        ('format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.guarded]\nfiles = {}\n', ["non-empty files"]),
        (
            'format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.guarded]\nfiles = {act = "a.npz"}\ninputs = 3\n',
            ["3"],
        ),
        (
            'format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.guarded]\nfiles = {act = "a.npz"}\n'
            'calibration = {model = "paper", size = ["--configs", "4"]}\n',
            ["[systems.Foo.guarded] calibration", "model = one of ['act']", "'paper'"],
        ),
        (
            'format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.guarded]\nfiles = {act = "a.npz"}\n'
            'calibration = {model = "act", size = ["--configs", 4]}\n',
            ["size = [strings]"],
        ),
        (
            'format = "rmm-lrmm-shipped"\nversion = 1\n[systems.Foo.guarded]\nfiles = {act = "a.npz"}\n'
            'calibration = {model = "act", size = [], seed = 3}\n',
            ["'seed'"],
        ),
    ],
)
def test_a_malformed_registration_is_refused_naming_the_file_and_the_entry(tmp_path, text, words):
    path = tmp_path / REGISTRATION
    path.write_text(text)
    with pytest.raises(ValueError, match=REGISTRATION) as e:
        _read_registration(path)
    for w in words:
        assert w in str(e.value)


def test_calibration_reads_each_shipped_model_and_its_labelling_from_the_registration():
    table = calibrated()
    assert list(table) == [s.name for s in SYSTEMS if s.name in table]  # the table's order
    assert table["Dubins3DMaze"] == {
        "env": ["--env", "Dubins3DMaze-v0", "--env-opt", 'maze_kind="mixed"', "--configs-per-shard", "1"],
        "model": "dubins3d_maze.npz",
        "size": ["--configs", "4", "--samples-per-config", "512"],
    }
    assert table["Dubins4D"]["env"] == ["--env", "Dubins4DGuarded-v0"]
    assert table["QuadrotorRoom"]["model"] == "quadrotor_cmd_act.npz"
    assert "Dubins4DMap" not in table  # it reads the Dubins4D model: no calibration of its own
