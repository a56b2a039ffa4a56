"""The env naming scheme (rmm_envs.catalog): today's ids, the ids results are keyed under, and former
ids read back from stored records under today's id (never registered, never warned about)."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import gymnasium as gym
import pytest

import rmm_envs
from rmm_envs.catalog import FORMER_IDS, current_id, stored_id


def test_the_users_id_is_todays_id_for_the_circles_world_and_keys_stay_stable():
    assert gym.spec("Dubins4DParallel-v0").entry_point == "rmm_envs.systems.dubins4d.env:parallel_env"
    assert gym.spec("Dubins4DGuarded-v0").entry_point == "rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv"
    # results stored before the ids settled keep their keys: the same stored id as then
    assert stored_id("Dubins4DParallel-v0") == "Dubins4DParallel-v0"
    assert stored_id("Dubins4DGuarded-v0") == "Dubins4DCircles-v0"
    assert stored_id("Dubins4DMapGuarded-v0") == "Dubins4DMap-v0"
    assert stored_id("QuadrotorRoom-v0") == current_id("QuadrotorRoom-v0") == "QuadrotorRoom-v0"


def test_former_ids_are_read_back_under_todays_id_and_are_not_registered():
    assert FORMER_IDS == {
        "Dubins4DCircles-v0": "Dubins4DGuarded-v0",
        "Dubins4DMap-v0": "Dubins4DMapGuarded-v0",
        "Dubins4DCirclesGuarded-v0": "Dubins4DGuarded-v0",
        "Dubins4DCirclesParallel-v0": "Dubins4DParallel-v0",
    }
    for old, new in FORMER_IDS.items():
        assert old not in gym.registry and old not in rmm_envs.ENV_IDS and new in rmm_envs.ENV_IDS
        assert current_id(old) == current_id(new) == new
        assert stored_id(old) == stored_id(new)
    with pytest.raises(gym.error.NameNotFound):
        gym.make("Dubins4DCirclesParallel-v0")


def test_making_the_users_id_never_warns_in_a_fresh_interpreter():
    code = "import gymnasium as gym, rmm_envs; gym.make('Dubins4DParallel-v0').reset(seed=0)"
    done = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make_vec("Dubins4DGuarded-v0", num_envs=2, vectorization_mode="vector_entry_point")
    assert type(env).__name__ == "Dubins4DCirclesVectorEnv"


def test_a_former_id_on_the_command_line_is_refused_naming_it(tmp_path, capsys):
    from rmm_bench.cli import main as bench

    assert (
        bench(
            [
                "--agent",
                "inactive",
                "--env",
                "Dubins4DCirclesParallel-v0",
                "--episodes",
                "1",
                "--no-progress",
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 2
    )
    assert "Dubins4DCirclesParallel-v0" in capsys.readouterr().err


def test_a_dataset_made_under_a_former_id_is_the_same_dataset_under_todays():
    from rmm_envs.risk.dataset import identity

    assert identity({"env_id": "Dubins4DCircles-v0", "seed": 1}) == identity(
        {"env_id": "Dubins4DGuarded-v0", "seed": 1}
    )
    assert identity({"env_id": "Dubins3DMaze-v0"}) != identity({"env_id": "Dubins3DMazeGuarded-v0"})


# ------------------------------------------------------------------ one table per system
def test_ids_registration_and_twins_come_from_the_table():
    from rmm_envs.catalog import ENV_VARIANTS, GUARDED_VARIANTS, SYSTEMS

    assert rmm_envs.ENV_IDS == tuple(s.name + ENV_VARIANTS[k] for s in SYSTEMS for k in ENV_VARIANTS if k in s.envs)
    assert rmm_envs.GUARDIAN_ENV_IDS == tuple(
        s.name + ENV_VARIANTS[k] for s in SYSTEMS for k in GUARDED_VARIANTS if k in s.envs
    )
    assert len(set(rmm_envs.ENV_IDS)) == len(rmm_envs.ENV_IDS) == 14
    for s in SYSTEMS:
        for variant, entry in s.envs.items():
            spec = gym.spec(s.env_id(variant))
            assert spec.entry_point == entry
            assert spec.vector_entry_point == (s.vector if variant == "guarded" else None)
    assert (
        gym.spec("Dubins4DGuarded-v0").vector_entry_point == "rmm_envs.systems.dubins4d.vector:Dubins4DCirclesVectorEnv"
    )
    with pytest.raises(KeyError, match="Dubins4D has no plain env"):
        SYSTEMS[0].env_id("plain")


def test_every_reference_of_the_table_imports():
    from gymnasium.envs.registration import load_env_creator

    from rmm_envs.adapters.base import SimulatorScene
    from rmm_envs.autonomy import SafeDefault
    from rmm_envs.catalog import SYSTEMS
    from rmm_envs.scenes.base import SceneBase

    for s in SYSTEMS:
        for ref in (*s.envs.values(), s.dynamics, s.driver, *((s.vector,) if s.vector else ())):
            assert callable(load_env_creator(ref)), ref
        assert all(issubclass(load_env_creator(ref), (SceneBase, SimulatorScene)) for ref in s.scenes)
        assert issubclass(load_env_creator(s.safe_default), SafeDefault)


@pytest.mark.parametrize(
    "name", ["Dubins4D", "Dubins4DMap", "Dubins3DMaze", "QuadrotorRoom", "CartPole", "InvertedPendulum"]
)
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

    assert [
        (s.name, k) for s, k in map(system_of, ("Dubins4DParallel-v0", "QuadrotorRoom-v0", "Dubins4DMapGuarded-v0"))
    ] == [("Dubins4D", "parallel"), ("QuadrotorRoom", "plain"), ("Dubins4DMap", "guarded")]
    with pytest.raises(KeyError, match="'CartPole-v1' is not an env of this package's systems"):
        system_of("CartPole-v1")


def test_the_cli_help_and_the_docs_list_name_the_table_s_ids():
    import sys
    from pathlib import Path

    from rmm_bench.run_args import run_parser, sweep_parser
    from rmm_envs.catalog import FORMER_IDS, SYSTEMS, env_help
    from rmm_envs.cli import build_parser

    assert env_help() == (
        "Dubins4DParallel-v0, Dubins4DMapParallel-v0, Dubins3DMazeParallel-v0, "
        "QuadrotorRoomParallel-v0, CartPoleParallel-v0, InvertedPendulumParallel-v0 (non-blocking) or "
        "Dubins4DGuarded-v0, Dubins4DMapGuarded-v0, Dubins3DMazeGuarded-v0, "
        "QuadrotorRoomGuarded-v0, CartPoleGuarded-v0, InvertedPendulumGuarded-v0 (blocking) in this package"
    )
    for parser in (run_parser(""), sweep_parser()):
        env = next(a for a in parser._actions if a.dest == "env")
        assert env_help() in env.help and env.default == "Dubins4DParallel-v0"
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
    assert sum(f"`{i}`" in line for line in rows for i in rmm_envs.ENV_IDS) == len(rmm_envs.ENV_IDS) + len(FORMER_IDS)
    assert sum(f"`{i}`" in line for line in rows for i in FORMER_IDS) == len(
        FORMER_IDS
    )  # a row each: record id, today's
    assert set(gen.env_pages()) == {p.path for s in SYSTEMS for p in s.pages}


def test_a_new_table_entry_is_registered_listed_and_helped(monkeypatch):
    from rmm_envs import catalog

    toy = catalog.SystemSpec(
        name="ToyCircles",
        blurb="a toy",
        dynamics="rmm_envs.systems.dubins4d.dynamics:Dubins4D",
        scenes=("rmm_envs.systems.dubins4d.scene:Dubins4DScene",),
        envs={"guarded": "rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv"},
    )
    last = catalog.env_ids(("guarded",))[-1]  # the table's last blocking env so far
    monkeypatch.setattr(catalog, "SYSTEMS", (*catalog.SYSTEMS, toy))
    try:
        catalog.register()
        assert gym.spec("ToyCirclesGuarded-v0").entry_point == "rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv"
        assert catalog.env_ids()[-1] == "ToyCirclesGuarded-v0" and "ToyCirclesGuarded-v0" in catalog.guardian_env_ids()
        assert f"{last}, ToyCirclesGuarded-v0 (blocking)" in catalog.env_help()
        assert catalog.system_of("ToyCirclesGuarded-v0") == (toy, "guarded")
    finally:
        gym.registry.pop("ToyCirclesGuarded-v0", None)


def test_shipped_models_are_keyed_by_system_and_found_by_every_id():
    from rmm_envs.catalog import GUARDED_VARIANTS, SYSTEMS
    from rmm_guardians.lrmm.model import SHIPPED, SHIPPED_BY_SYSTEM

    names = {s.name: s for s in SYSTEMS}
    assert set(SHIPPED_BY_SYSTEM) <= set(names)
    for name, variants in SHIPPED_BY_SYSTEM.items():
        for variant, ship in variants.items():
            assert variant in ("plain", "guarded")
            for env_id in names[name].ids(("plain",) if variant == "plain" else GUARDED_VARIANTS):
                assert SHIPPED[env_id] is ship
    assert list(SHIPPED) == [i for i in rmm_envs.ENV_IDS if i in SHIPPED]  # current ids only (a system may ship none)
    assert SHIPPED["Dubins4DParallel-v0"] is SHIPPED["Dubins4DParallel-v0"] and "Dubins4DMap-v0" in SHIPPED
    assert SHIPPED.get("CartPole-v1") is None and "CartPole-v1" not in SHIPPED


def test_the_guardians_the_table_lists_are_those_the_benchmark_accepts():
    from rmm_bench.run_args import parse_run
    from rmm_bench.run_checks import check_runs
    from rmm_envs.catalog import SYSTEMS
    from rmm_guardians.registry import BUILTIN

    for s in SYSTEMS:
        cfg = parse_run(
            [
                "--agent",
                ",".join(BUILTIN),
                "--env",
                s.env_id("guarded"),
                "--clock",
                "fixed:1",
                "--episodes",
                "1",
                "--no-progress",
                "--workers",
                "1",
            ],
            "",
        )
        meta = check_runs(cfg.agent_runs(), skip_inapplicable=True)
        assert tuple(a for a in BUILTIN if "skipped" not in meta[a]) == tuple(a for a in BUILTIN if a in s.guardians), (
            s.name
        )


# ------------------------------------------------------------------ one path for every system


def test_the_built_in_systems_register_through_the_entry_point_group_a_package_of_yours_uses():
    from importlib.metadata import entry_points

    from rmm_envs import builtin
    from rmm_envs.catalog import ENTRY_POINT_GROUP, SYSTEMS

    own = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.dist.name == "rmm-envs"}
    assert own == {"rmm_envs": "rmm_envs.builtin:systems"}
    assert builtin.systems() == SYSTEMS[: len(builtin.systems())]
    assert [s.name for s in builtin.systems()] == [
        "Dubins4D",
        "Dubins4DMap",
        "Dubins3DMaze",
        "QuadrotorRoom",
        "CartPole",
        "InvertedPendulum",
    ]


def test_every_view_and_doomed_test_the_table_names_imports():
    from rmm_envs.catalog import SYSTEMS, load_ref

    named = {s.name: (s.view, s.doomed_test) for s in SYSTEMS}
    assert {n for n, (_, test) in named.items() if test} == {"Dubins4D", "Dubins4DMap", "Dubins3DMaze", "QuadrotorRoom"}
    assert all(view for view, _ in named.values())
    for view, test in named.values():
        for ref in (view, test):
            assert ref is None or callable(load_ref(ref)), ref


def test_an_env_s_system_is_found_by_its_id_then_by_its_class():
    from rmm_envs.catalog import system_of_env
    from rmm_envs.systems.maze.env import Dubins3DMazeEnv
    from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv

    def found(env):
        s = system_of_env(env)
        return None if s is None else (s[0].name, s[1])

    assert found(gym.make("Dubins4DParallel-v0")) == ("Dubins4D", "parallel")
    assert found(gym.make("Dubins3DMaze-v0")) == ("Dubins3DMaze", "plain")
    assert found(Dubins3DMazeGuardedEnv()) == ("Dubins3DMaze", "guarded")  # built without gym.make
    assert found(Dubins3DMazeEnv()) == ("Dubins3DMaze", "plain")
    assert found(gym.make("CartPole-v1")) == ("CartPole", "dynamics")  # the CartPole system's simulator
    assert found(gym.make("MountainCar-v0")) is None


def test_add_system_refuses_a_second_system_of_a_name_or_an_id_taken_by_another_env():
    from rmm_envs.catalog import SYSTEMS, SystemSpec, add_system

    twin = SystemSpec(name="Dubins4D", blurb="", dynamics="x:Y", scenes=(), envs={"guarded": "x:Y"})
    with pytest.raises(ValueError, match="a system named 'Dubins4D' is already registered"):
        add_system(twin)
    gym.register("ClashGuarded-v0", entry_point="rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv")
    try:
        clash = SystemSpec(name="Clash", blurb="", dynamics="x:Y", scenes=(), envs={"guarded": "x:Y"})
        with pytest.raises(ValueError, match="'ClashGuarded-v0' is already registered with entry point"):
            add_system(clash)
    finally:
        gym.registry.pop("ClashGuarded-v0", None)
    with pytest.raises(TypeError, match="a system is a rmm_envs.catalog.SystemSpec"):
        add_system("Dubins4D")
    add_system(SYSTEMS[0])  # already in the table: nothing changes
    assert rmm_envs.catalog.SYSTEMS == SYSTEMS


TOY_SYSTEM = """
from rmm_envs.catalog import SystemSpec
from rmm_envs.starts import StartAssessment
from rmm_envs.systems.dubins4d.view import Dubins4DView


def spec():
    return SystemSpec(
        name="ToyRobot",
        blurb="the circles car under another name",
        dynamics="rmm_envs.systems.dubins4d.dynamics:Dubins4D",
        scenes=("rmm_envs.systems.dubins4d.scene:Dubins4DScene",),
        envs={"guarded": "rmm_envs.systems.dubins4d.env:Dubins4DGuardedEnv"},
        stored={"guarded": "ToyRobotOld-v0"},
        view="toyrobot:view",
        doomed_test="toyrobot:doomed",
    )


def view(env, size):
    return Dubins4DView(size // 2)


def doomed(env):
    return StartAssessment(True, "toy")
"""

TOY_CHECK = """
import warnings
warnings.simplefilter("always")
import gymnasium as gym
import rmm_envs
from rmm_envs.catalog import SYSTEMS, current_id
from rmm_envs.starts import assess_start
from rmm_envs.views import view_for

env = gym.make("ToyRobotGuarded-v0")
env.reset(seed=0)
print([s.name for s in SYSTEMS][-2:], current_id("ToyRobotOld-v0"), assess_start(env), view_for(env, 64).width)
"""


def test_a_package_s_system_registers_through_the_same_group_with_its_view_and_doomed_test(tmp_path):
    """A distribution on the path with a ``rmm_envs.systems`` entry point: importing rmm_envs
    registers its system after the built-ins, and its own view and doomed test serve its env
    (whose class is a built-in system's); a failing entry point is a warning, not an error."""
    (tmp_path / "toyrobot.py").write_text(TOY_SYSTEM)
    info = tmp_path / "toyrobot-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toyrobot\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[rmm_envs.systems]\nToyRobot = toyrobot:spec\nBroken = toyrobot:nothing\n")
    out = subprocess.run(
        [sys.executable, "-c", TOY_CHECK],
        env={**os.environ, "PYTHONPATH": str(tmp_path)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == (
        "['InvertedPendulum', 'ToyRobot'] ToyRobotGuarded-v0 StartAssessment(doomed=True, method='toy') 32"
    )
    assert "entry point Broken = 'toyrobot:nothing' of 'toyrobot' failed (AttributeError" in out.stderr
