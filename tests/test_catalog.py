"""The env naming scheme (rmm_envs.catalog): old ids are aliases that warn and build the new env."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs
from rmm_envs.catalog import RENAMED, canonical_id, stored_id


def test_renamed_ids_follow_the_scheme_and_are_not_current_ids():
    assert RENAMED == {"Dubins4DCircles-v0": "Dubins4DCirclesGuarded-v0", "Dubins4DParallel-v0": "Dubins4DCirclesParallel-v0",
                       "Dubins4DMap-v0": "Dubins4DMapGuarded-v0"}
    for old, new in RENAMED.items():
        assert old in gym.registry and new in rmm_envs.ENV_IDS and old not in rmm_envs.ENV_IDS
        assert canonical_id(old) == canonical_id(new) == new
        assert stored_id(old) == stored_id(new) == old
    assert canonical_id("QuadrotorRoom-v0") == stored_id("QuadrotorRoom-v0") == "QuadrotorRoom-v0"


@pytest.mark.parametrize("old", ["Dubins4DCircles-v0", "Dubins4DParallel-v0"])
def test_an_old_id_warns_at_the_callers_line_and_builds_the_same_env(old):
    new = RENAMED[old]
    kwargs = {"clock": "fixed:1"} if "Parallel" in new else {}
    with pytest.warns(DeprecationWarning, match=f"'{old}' was renamed '{new}'") as record:
        env_old = gym.make(old, **kwargs)
    assert record[0].filename == __file__  # shown by Python's default filter when a script makes it
    env_new = gym.make(new, **kwargs)
    assert type(env_old.unwrapped) is type(env_new.unwrapped)
    obs_old, _ = env_old.reset(seed=3)
    obs_new, _ = env_new.reset(seed=3)
    action = env_new.action_space.sample()
    np.testing.assert_array_equal(obs_old, obs_new)
    np.testing.assert_array_equal(env_old.step(action)[0], env_new.step(action)[0])


def test_the_new_ids_do_not_warn_and_the_vector_entry_point_moved_with_the_blocking_id():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make_vec("Dubins4DCirclesGuarded-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert type(env).__name__ == "Dubins4DCirclesVectorEnv"
    with pytest.warns(DeprecationWarning, match="'Dubins4DCircles-v0' was renamed"):
        old = gym.make_vec("Dubins4DCircles-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert type(old) is type(env)


def test_an_alias_accepts_what_its_new_id_accepts():
    from benchmarks.bench.checks import env_arguments

    assert env_arguments("Dubins4DParallel-v0") == env_arguments("Dubins4DCirclesParallel-v0") >= {"time_accel", "clock"}


def test_every_command_taking_an_env_id_takes_an_old_one_with_the_same_note(tmp_path, capsys):
    import json

    from rmm_envs.cli import build_parser
    from rmm_envs.risk.datagen import main as datagen

    note = "{}: --env Dubins4DCircles-v0 was renamed Dubins4DCirclesGuarded-v0 (the old id still works but will be removed)"
    assert build_parser().parse_args(["demo", "--env", "Dubins4DCircles-v0"]).env == "Dubins4DCirclesGuarded-v0"
    assert capsys.readouterr().err.splitlines() == [note.format("rmm-envs demo")]
    assert datagen(["--env", "Dubins4DCircles-v0", "--configs", "1", "--samples-per-config", "2", "--branches", "2",
                    "--depth", "1", "--no-progress", "--out", str(tmp_path / "d")]) == 0
    assert capsys.readouterr().err.splitlines() == [note.format("rmm-datagen")]
    assert json.loads((tmp_path / "d" / "metadata.json").read_text())["env_id"] == "Dubins4DCirclesGuarded-v0"


def test_a_dataset_made_under_an_old_id_is_the_same_dataset_under_the_new_one():
    from rmm_envs.risk.dataset import identity

    assert identity({"env_id": "Dubins4DCircles-v0", "seed": 1}) == identity({"env_id": "Dubins4DCirclesGuarded-v0", "seed": 1})
    assert identity({"env_id": "Dubins3DMaze-v0"}) != identity({"env_id": "Dubins3DMazeGuarded-v0"})


# ------------------------------------------------------------------ one table per system
def test_ids_registration_and_twins_come_from_the_table():
    from rmm_envs.catalog import GUARDED_KINDS, KINDS, SYSTEMS

    assert rmm_envs.ENV_IDS == tuple(s.name + KINDS[k] for s in SYSTEMS for k in KINDS if k in s.envs)
    assert rmm_envs.GUARDIAN_ENV_IDS == tuple(s.name + KINDS[k] for s in SYSTEMS for k in GUARDED_KINDS if k in s.envs)
    assert len(set(rmm_envs.ENV_IDS)) == len(rmm_envs.ENV_IDS) == 14
    for s in SYSTEMS:
        for kind, entry in s.envs.items():
            spec = gym.spec(s.env_id(kind))
            assert spec.entry_point == entry
            assert spec.vector_entry_point == (s.vector if kind == "guarded" else None)
    assert gym.spec("Dubins4DCirclesGuarded-v0").vector_entry_point == "rmm_envs.envs.dubins4d_vector:Dubins4DCirclesVectorEnv"
    with pytest.raises(KeyError, match="Dubins4DCircles has no plain env"):
        SYSTEMS[0].env_id("plain")


def test_every_reference_of_the_table_imports():
    from gymnasium.envs.registration import load_env_creator

    from rmm_envs.autonomy import SafeDefault
    from rmm_envs.catalog import SYSTEMS
    from rmm_envs.adapters.base import SimulatorScene
    from rmm_envs.scenes.base import SceneBase

    for s in SYSTEMS:
        for ref in (*s.envs.values(), s.dynamics, s.driver, *((s.vector,) if s.vector else ())):
            assert callable(load_env_creator(ref)), ref
        assert all(issubclass(load_env_creator(ref), (SceneBase, SimulatorScene)) for ref in s.scenes)
        assert issubclass(load_env_creator(s.safe_default), SafeDefault)


@pytest.mark.parametrize("name", ["Dubins4DCircles", "Dubins4DMap", "Dubins3DMaze", "QuadrotorRoom", "CartPole",
                                  "InvertedPendulum"])
def test_the_driver_and_safe_default_the_table_names_are_those_its_guarded_env_uses(name):
    from gymnasium.envs.registration import load_env_creator

    from rmm_envs.catalog import SYSTEMS

    s = next(s for s in SYSTEMS if s.name == name)
    pytest.importorskip({"map": "pymunk", "quadrotor": "pybullet", "mujoco": "mujoco"}.get(s.extra, "numpy"))
    env = gym.make(s.env_id("guarded"))
    env.reset(seed=0)
    driver = load_env_creator(s.driver)
    assert type(env.action_space.safe_default) is load_env_creator(s.safe_default)
    assert [k for k, v in vars(env.unwrapped).items() if type(v) is driver], f"{name}: no {driver.__name__} drives it"
    env.close()


def test_system_of_finds_each_id_and_refuses_others():
    from rmm_envs.catalog import system_of

    assert [(s.name, k) for s, k in map(system_of, ("Dubins4DParallel-v0", "QuadrotorRoom-v0", "Dubins4DMapGuarded-v0"))] == \
        [("Dubins4DCircles", "parallel"), ("QuadrotorRoom", "plain"), ("Dubins4DMap", "guarded")]
    with pytest.raises(KeyError, match="'CartPole-v1' is not an env of this package's systems"):
        system_of("CartPole-v1")


def test_the_cli_help_and_the_docs_list_name_the_table_s_ids():
    import sys
    from pathlib import Path

    from benchmarks.bench.args import run_parser, sweep_parser
    from rmm_envs.catalog import RENAMED, SYSTEMS, env_help
    from rmm_envs.cli import build_parser

    assert env_help() == ("Dubins4DCirclesParallel-v0, Dubins4DMapParallel-v0, Dubins3DMazeParallel-v0, "
                          "QuadrotorRoomParallel-v0, CartPoleParallel-v0, InvertedPendulumParallel-v0 (non-blocking) or "
                          "Dubins4DCirclesGuarded-v0, Dubins4DMapGuarded-v0, Dubins3DMazeGuarded-v0, "
                          "QuadrotorRoomGuarded-v0, CartPoleGuarded-v0, InvertedPendulumGuarded-v0 (blocking) in this package")
    for parser in (run_parser(""), sweep_parser()):
        env = next(a for a in parser._actions if a.dest == "env")
        assert env_help() in env.help and env.default == "Dubins4DCirclesParallel-v0"
    demo = next(a for a in build_parser()._actions if a.dest == "command").choices["demo"]
    assert next(a for a in demo._actions if a.dest == "env").choices == list(rmm_envs.GUARDIAN_ENV_IDS)
    docs = Path(__file__).resolve().parents[1] / "docs"
    sys.path.insert(0, str(docs))
    try:
        import gen
    finally:
        sys.path.remove(str(docs))
    page = gen.env_list_page()
    assert (docs / "environments" / "index.md").read_text() == page
    rows = [line for line in page.splitlines() if line.startswith("| ") and "`" in line]
    assert sum(f"`{i}`" in line for line in rows for i in rmm_envs.ENV_IDS) == len(rmm_envs.ENV_IDS) + len(RENAMED)
    assert set(gen.env_pages()) == {p.path for s in SYSTEMS for p in s.pages}


def test_a_new_table_entry_is_registered_listed_and_helped(monkeypatch):
    from rmm_envs import catalog

    toy = catalog.SystemSpec(name="ToyCircles", blurb="a toy", dynamics="rmm_envs.systems.dubins4d:Dubins4D",
                             scenes=("rmm_envs.scenes.dubins4d:Dubins4DScene",),
                             envs={"guarded": "rmm_envs.envs.dubins4d:Dubins4DCirclesEnv"})
    last = catalog.env_ids(("guarded",))[-1]  # the table's last blocking env so far
    monkeypatch.setattr(catalog, "SYSTEMS", (*catalog.SYSTEMS, toy))
    try:
        catalog.register()
        assert gym.spec("ToyCirclesGuarded-v0").entry_point == "rmm_envs.envs.dubins4d:Dubins4DCirclesEnv"
        assert catalog.env_ids()[-1] == "ToyCirclesGuarded-v0" and "ToyCirclesGuarded-v0" in catalog.guardian_env_ids()
        assert f"{last}, ToyCirclesGuarded-v0 (blocking)" in catalog.env_help()
        assert catalog.system_of("ToyCirclesGuarded-v0") == (toy, "guarded")
    finally:
        gym.registry.pop("ToyCirclesGuarded-v0", None)


def test_shipped_models_are_keyed_by_system_and_found_by_every_id():
    from guardians.lrmm.model import SHIPPED, SHIPPED_BY_SYSTEM
    from rmm_envs.catalog import GUARDED_KINDS, SYSTEMS

    names = {s.name: s for s in SYSTEMS}
    assert set(SHIPPED_BY_SYSTEM) <= set(names)
    for name, kinds in SHIPPED_BY_SYSTEM.items():
        for kind, ship in kinds.items():
            assert kind in ("plain", "guarded")
            for env_id in names[name].ids(("plain",) if kind == "plain" else GUARDED_KINDS):
                assert SHIPPED[env_id] is ship
    assert list(SHIPPED) == [i for i in rmm_envs.ENV_IDS if i in SHIPPED]  # current ids only (a system may ship none)
    assert SHIPPED["Dubins4DParallel-v0"] is SHIPPED["Dubins4DCirclesParallel-v0"] and "Dubins4DMap-v0" in SHIPPED
    assert SHIPPED.get("CartPole-v1") is None and "CartPole-v1" not in SHIPPED


def test_the_guardians_the_table_lists_are_those_the_benchmark_accepts():
    from benchmarks.bench.args import parse_run
    from benchmarks.bench.checks import check_runs
    from guardians.registry import BUILTIN
    from rmm_envs.catalog import SYSTEMS

    for s in SYSTEMS:
        cfg = parse_run(["--agent", ",".join(BUILTIN), "--env", s.env_id("guarded"), "--clock", "fixed:1", "--episodes", "1",
                         "--no-progress", "--workers", "1"], "")
        meta = check_runs(cfg.agent_runs(), skip_inapplicable=True)
        assert tuple(a for a in BUILTIN if "skipped" not in meta[a]) == tuple(a for a in BUILTIN if a in s.guardians), s.name
