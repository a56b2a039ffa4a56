"""Guardians dispatch on the dynamics an env's action space states (rmm_envs.autonomy's
SystemContract), never on control names; third-party envs state the dynamics "generic"."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401  (registers the ids)
from rmm_envs.autonomy import GENERIC, GuardianActionSpace, SystemContract, contract
from rmm_envs.systems.dubins4d import dynamics as dubins4d
from rmm_envs.systems.maze import dynamics as dubins3d
from rmm_envs.systems.quadrotor import control as quadrotor_control
from rmm_guardians.cbf import CBFGuardian, CBFPaperGuardian
from rmm_guardians.cbf.maze import MazeCBFGuardian
from rmm_guardians.dispatch import delegate_arguments, require_dynamics
from rmm_guardians.hj.guardian import HJGuardian
from rmm_guardians.system_checks import quadrotor_only


@pytest.mark.parametrize(
    "env_id, dynamics_name, controls",
    [
        ("Dubins4DParallel-v0", "dubins4d", ("turnrate_ctrl", "accel_ctrl")),
        ("Dubins4DGuarded-v0", "dubins4d", ("turnrate_ctrl", "accel_ctrl")),
        ("Dubins3DMazeParallel-v0", "dubins3d", ("turnrate_ctrl",)),
        ("QuadrotorRoomParallel-v0", "quadrotor", ("vforward_ctrl", "vleft_ctrl", "vup_ctrl", "yawrate_ctrl")),
        ("CartPoleParallel-v0", "generic", ("force_ctrl",)),
    ],
)
def test_each_env_states_its_system_in_its_action_space(env_id, dynamics_name, controls):
    if env_id.startswith("Quadrotor"):
        pytest.importorskip("pybullet")
    env = gym.make(env_id)
    c = contract(env.action_space)
    assert c == env.action_space.contract and c.dynamics_name == dynamics_name and c.controls == controls
    assert c.control_low == tuple(env.action_space.control_low.tolist())
    assert c.control_high == tuple(env.action_space.control_high.tolist())
    assert c.safe_default is env.action_space.safe_default and c.safe_default is not None
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.dynamics_name = "other"
    env.close()


def test_the_systems_own_their_dynamics_names_and_the_default_is_generic():
    assert (dubins4d.DYNAMICS_NAME, dubins3d.DYNAMICS_NAME, quadrotor_control.DYNAMICS_NAME, GENERIC) == (
        "dubins4d",
        "dubins3d",
        "quadrotor",
        "generic",
    )
    space = GuardianActionSpace(("a",), [-1.0], [2.0])
    assert space.contract == SystemContract("generic", ("a",), (-1.0,), (2.0,), None, None)
    for bad in ("", None, 3):
        with pytest.raises(ValueError, match=f"dynamics_name must be a non-empty dynamics name .*got {bad!r}"):
            GuardianActionSpace(("a",), [-1.0], [1.0], dynamics_name=bad)
    with pytest.raises(TypeError, match="GuardianActionSpace"):
        contract(gym.spaces.Discrete(2))


def test_the_dynamics_not_the_control_names_pick_the_guardian():
    # the maze car's control names under the generic dynamics: no guardian that models a system serves it
    lookalike = GuardianActionSpace(dubins3d.CONTROLS, [-0.2], [0.2])
    for g in (CBFGuardian(), HJGuardian()):
        with pytest.raises(
            ValueError,
            match=f"guardian {g.name!r} applies to Dubins4D envs and the maze car .*and the "
            r"quadrotor .*this env's dynamics are 'generic'",
        ):
            g.check_spaces(None, lookalike)
    # the same names under the maze car's dynamics: the maze guardian
    maze = GuardianActionSpace(dubins3d.CONTROLS, [-0.2], [0.2], dynamics_name="dubins3d")
    g = CBFGuardian()
    g.check_spaces(None, maze)
    assert isinstance(g._delegate_for(maze), MazeCBFGuardian) and g._delegate_for(maze) is g._delegate_for(maze)
    assert g.served() == ("dubins3d", "quadrotor") and CBFPaperGuardian().served() == ()
    with pytest.raises(ValueError, match="'cbf-paper' applies to Dubins4D envs only"):
        CBFPaperGuardian().check_spaces(None, maze)


def test_a_space_whose_controls_contradict_its_dynamics_is_refused_naming_both():
    wrong = GuardianActionSpace(("turn", "accel"), [-0.25, -0.5], [0.25, 0.5], dynamics_name="dubins4d")
    with pytest.raises(
        ValueError,
        match=r"guardian 'cbf': this env states dynamics 'dubins4d', whose controls are "
        r"\('turnrate_ctrl', 'accel_ctrl'\), but its action space's controls are "
        r"\('turn', 'accel'\)",
    ):
        CBFGuardian().check_spaces(None, wrong)


def test_require_dynamics_returns_the_space_of_its_dynamics():
    space = GuardianActionSpace(quadrotor_control.CONTROLS, [-1.0] * 4, [1.0] * 4, dynamics_name="quadrotor")
    controls = quadrotor_control.CONTROLS
    assert require_dynamics(CBFGuardian(), space, "quadrotor", controls, "models the quadrotor") is space
    with pytest.raises(
        ValueError, match=r"guardian 'cbf' models the quadrotor \(dynamics 'quadrotor'.*dynamics are 'dubins3d'"
    ):
        require_dynamics(
            CBFGuardian(),
            GuardianActionSpace(("turnrate_ctrl",), [-1.0], [1.0], dynamics_name="dubins3d"),
            "quadrotor",
            controls,
            "models the quadrotor",
        )


def test_a_third_party_env_is_served_by_the_model_free_guardians_only():
    from rmm_guardians.baselines import BrakesGuardian

    env = gym.make("CartPoleParallel-v0")
    assert env.action_space.dynamics_name == GENERIC
    BrakesGuardian().check_spaces(env.observation_space, env.action_space)
    for g in (CBFGuardian(), HJGuardian()):
        with pytest.raises(ValueError, match="this env's dynamics are 'generic'"):
            g.check_spaces(env.observation_space, env.action_space)
    obs, info = env.reset(seed=0)
    b = BrakesGuardian()
    b.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    a = b.act(obs, info)
    assert a["active_ctrl"] == 1 and np.all(np.isfinite(a[env.action_space.controls[0]]))
    env.close()


def test_the_refusals_say_exactly_what_each_guardian_serves():
    lookalike = GuardianActionSpace(dubins3d.CONTROLS, [-0.2], [0.2])
    with pytest.raises(ValueError) as e:
        CBFGuardian().check_spaces(None, lookalike)
    assert str(e.value) == (
        "guardian 'cbf' applies to Dubins4D envs and the maze car (controls ('turnrate_ctrl',)) and the quadrotor "
        "(controls ('vforward_ctrl', 'vleft_ctrl', 'vup_ctrl', 'yawrate_ctrl')): it models the Dubins4D car among "
        "circular obstacles (dynamics 'dubins4d', controls ('turnrate_ctrl', 'accel_ctrl')); this env's dynamics are "
        "'generic' and its controls are ('turnrate_ctrl',)"
    )
    with pytest.raises(ValueError) as e:
        CBFPaperGuardian().check_spaces(None, lookalike)
    assert str(e.value).startswith("guardian 'cbf-paper' applies to Dubins4D envs only: it models the Dubins4D car")
    with pytest.raises(ValueError) as e:
        MazeCBFGuardian().check_spaces(None, lookalike)
    assert str(e.value) == (
        "guardian 'cbf' (maze) models the constant-speed maze car among walls (dynamics 'dubins3d', "
        "controls ('turnrate_ctrl',)); this env's dynamics are 'generic' and its controls are "
        "('turnrate_ctrl',)"
    )
    lopsided = GuardianActionSpace(dubins3d.CONTROLS, [-0.1], [0.2], dynamics_name="dubins3d")
    with pytest.raises(ValueError) as e:
        MazeCBFGuardian().check_spaces(None, lopsided)
    assert str(e.value) == (
        "guardian 'cbf' (maze) needs a turn-rate bound symmetric about 0 and wider than a point "
        "([-b, b] with b > 0), got [-0.1, 0.2]"
    )
    MazeCBFGuardian().check_spaces(
        None, GuardianActionSpace(dubins3d.CONTROLS, [-0.2], [0.2], dynamics_name="dubins3d")
    )


def test_reset_hands_the_episode_to_the_delegate_of_the_space_s_dynamics_and_back():
    from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv

    maze_env = Dubins3DMazeGuardedEnv()
    obs, info = maze_env.reset(seed=3)
    priv = maze_env.privileged()
    g = CBFGuardian()
    assert g.delegate is None
    g.reset(
        seed=0,
        observation_space=maze_env.observation_space,
        action_space=maze_env.action_space,
        privileged=lambda: priv,
    )
    assert isinstance(g.delegate, MazeCBFGuardian) and g.delegate is g._delegate_for(maze_env.action_space)
    assert g.delegate.name == "cbf"
    a = g.act(obs, info)
    assert set(a) == {"active_ctrl", "turnrate_ctrl"}  # the maze car's control, decided by the delegate
    car = gym.make("Dubins4DGuarded-v0")
    car.reset(seed=0)
    g.reset(
        seed=0,
        observation_space=car.observation_space,
        action_space=car.action_space,
        privileged=car.unwrapped.privileged,
    )
    assert g.delegate is None  # the Dubins4D car: the class's own episode
    car.close()
    maze_env.close()


def test_delegate_arguments_merge_check_and_refuse():
    assert delegate_arguments(MazeCBFGuardian, "maze", False, {"solver": "osqp"}) is None
    assert delegate_arguments(MazeCBFGuardian, "maze", None, {"solver": "osqp"}) == {"solver": "osqp"}
    assert delegate_arguments(MazeCBFGuardian, "maze", {"margin": 2.0}, {"margin": 1.0, "solver": "osqp"}) == {
        "margin": 2.0,
        "solver": "osqp",
    }
    with pytest.raises(ValueError) as e:
        delegate_arguments(MazeCBFGuardian, "maze", [1], {})
    assert str(e.value) == "maze must be a dict of rmm_guardians.cbf.maze.MazeCBFGuardian arguments (or False), got [1]"
    with pytest.raises((TypeError, ValueError)):
        delegate_arguments(MazeCBFGuardian, "maze", {"no_such_argument": 1}, {})


def test_the_obstacle_shapes_and_the_quadrotor_s_command_box_are_checked_by_value():
    car = dubins4d.CONTROLS
    circles = GuardianActionSpace(
        car, [-0.25, -0.5], [0.25, 0.5], dynamics_name="dubins4d", obstacle_shapes=("circle",)
    )
    CBFGuardian().check_spaces(None, circles)
    mixed = GuardianActionSpace(
        car, [-0.25, -0.5], [0.25, 0.5], dynamics_name="dubins4d", obstacle_shapes=("circle", "polygon")
    )
    with pytest.raises(ValueError) as e:
        CBFGuardian().check_spaces(None, mixed)
    assert str(e.value) == (
        "guardian 'cbf' models circular obstacles only, and this env's world also has polygon "
        "obstacles (a map with shapes ['circle', 'polygon']); use a map of circles only, or a "
        "guardian that needs no obstacle geometry (lrmm, brakes)"
    )
    quad = quadrotor_control.CONTROLS
    box = GuardianActionSpace(quad, [-1.0] * 4, [1.0] * 4, dynamics_name="quadrotor")
    assert quadrotor_only(CBFGuardian(), box) is box
    edge = GuardianActionSpace(quad, [0.0, -1.0, -1.0, -1.0], [1.0, 0.0, 1.0, 1.0], dynamics_name="quadrotor")
    assert quadrotor_only(CBFGuardian(), edge) is edge  # zero on the box's edge still contains hover
    no_hover = GuardianActionSpace(quad, [0.5, -1.0, -1.0, -1.0], [1.0, 1.0, 1.0, 1.0], dynamics_name="quadrotor")
    with pytest.raises(ValueError) as e:
        quadrotor_only(CBFGuardian(), no_hover)
    assert str(e.value) == (
        "guardian 'cbf' (quadrotor) needs a command box that contains the zero command (hover) and "
        "is wider than a point in each of ('vforward_ctrl', 'vleft_ctrl', 'vup_ctrl', 'yawrate_ctrl') "
        "(low <= 0 <= high, low < high), got low [0.5, -1.0, -1.0, -1.0] and high [1.0, 1.0, 1.0, 1.0]"
    )
    with pytest.raises(
        ValueError,
        match=r"^guardian 'cbf' \(quadrotor\) models the quadrotor's velocity command in a "
        r"room \(dynamics 'quadrotor'.*this env's dynamics are 'dubins4d'",
    ):
        quadrotor_only(CBFGuardian(), circles)


def test_every_non_circle_shape_of_a_map_is_named_in_the_refusal():
    car = dubins4d.CONTROLS
    space = GuardianActionSpace(
        car, [-0.25, -0.5], [0.25, 0.5], dynamics_name="dubins4d", obstacle_shapes=("circle", "polygon", "segment")
    )
    for g in (CBFGuardian(), HJGuardian()):
        with pytest.raises(ValueError) as e:
            g.check_spaces(None, space)
        assert str(e.value) == (
            f"guardian {g.name!r} models circular obstacles only, and this env's world also has "
            "polygon, segment obstacles (a map with shapes ['circle', 'polygon', 'segment']); use a "
            "map of circles only, or a guardian that needs no obstacle geometry (lrmm, brakes)"
        )


def test_a_turn_rate_or_command_axis_of_zero_width_is_refused():
    from rmm_guardians.hj.maze import MazeHJGuardian

    # [0, 0] is symmetric about 0 and contains hover, but leaves the guardian no control to use
    for lo, hi in ((0.0, 0.0), (-0.0, 0.0)):
        still = GuardianActionSpace(dubins3d.CONTROLS, [lo], [hi], dynamics_name="dubins3d")
        for g in (MazeCBFGuardian(), MazeHJGuardian(), CBFGuardian(), HJGuardian()):
            with pytest.raises(ValueError) as e:
                g.check_spaces(None, still)
            assert str(e.value) == (
                f"guardian {g.name!r} (maze) needs a turn-rate bound symmetric about 0 and wider "
                f"than a point ([-b, b] with b > 0), got [{lo}, {hi}]"
            )
    tiny = GuardianActionSpace(dubins3d.CONTROLS, [-1e-9], [1e-9], dynamics_name="dubins3d")
    MazeCBFGuardian().check_spaces(None, tiny)
    quad = quadrotor_control.CONTROLS
    for axis in range(4):
        lo, hi = [-1.0] * 4, [1.0] * 4
        lo[axis] = hi[axis] = 0.0
        flat = GuardianActionSpace(quad, lo, hi, dynamics_name="quadrotor")
        with pytest.raises(ValueError) as e:
            quadrotor_only(CBFGuardian(), flat)
        assert str(e.value) == (
            "guardian 'cbf' (quadrotor) needs a command box that contains the zero command (hover) "
            f"and is wider than a point in each of {quad} (low <= 0 <= high, low < high), got low "
            f"{lo} and high {hi}"
        )
        with pytest.raises(ValueError, match=r"wider than a point"):
            HJGuardian().check_spaces(None, flat)


@pytest.mark.parametrize("make", [CBFGuardian, HJGuardian, CBFPaperGuardian])
def test_a_space_that_is_not_a_guardian_action_space_is_refused_by_name(make):
    env = gym.make("Dubins4DGuarded-v0")
    plain = gym.spaces.Box(-1.0, 1.0, (2,), np.float64)
    g = make()
    with pytest.raises(ValueError) as e:
        g.check_spaces(env.observation_space, plain)
    assert str(e.value) == (
        f"guardian {g.name!r} builds its actions through the env's action space: pass "
        "reset(action_space=env.action_space) with a rmm_envs.autonomy.GuardianActionSpace, "
        f"got {plain!r}"
    )
    # a reset without any action space: the same refusal, naming what was got (None)
    with pytest.raises(
        ValueError,
        match=f"^guardian {g.name!r} builds its actions through the env's action space: "
        r"pass reset\(action_space=env.action_space\) .*got None$",
    ):
        g.reset(seed=0, observation_space=env.observation_space, privileged=env.unwrapped.privileged)
    assert g.delegate is None
    env.close()


# ------------------------------------------------------------------ the methods' parts (rmm_guardians.parts)


def test_the_built_in_parts_are_declared_in_the_entry_point_group_a_package_of_yours_uses():
    from importlib.metadata import entry_points

    from rmm_guardians.cbf.quadrotor import QuadrotorCBFGuardian
    from rmm_guardians.cbf.settings import CBFSettings
    from rmm_guardians.hj.maze import MazeHJGuardian
    from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian
    from rmm_guardians.hj.settings import HJSettings
    from rmm_guardians.parts import ENTRY_POINT_GROUP, parts_of

    own = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.dist.name == "rmm-envs"}
    assert own == {
        "cbf.dubins3d": "rmm_guardians.cbf.maze:MazeCBFGuardian",
        "cbf.quadrotor": "rmm_guardians.cbf.quadrotor:QuadrotorCBFGuardian",
        "hj.dubins3d": "rmm_guardians.hj.maze:MazeHJGuardian",
        "hj.quadrotor": "rmm_guardians.hj.quadrotor:QuadrotorHJGuardian",
    }
    assert parts_of("cbf") == {"dubins3d": MazeCBFGuardian, "quadrotor": QuadrotorCBFGuardian}
    assert parts_of("hj") == {"dubins3d": MazeHJGuardian, "quadrotor": QuadrotorHJGuardian}
    assert parts_of("lrmm") == {}
    fields = {"cbf": set(CBFSettings.__dataclass_fields__), "hj": set(HJSettings.__dataclass_fields__)}
    for method, dynamics in (
        ("cbf", dubins3d),
        ("hj", dubins3d),
        ("cbf", quadrotor_control),
        ("hj", quadrotor_control),
    ):
        part = parts_of(method)[dynamics.DYNAMICS_NAME]
        assert part.controls == dynamics.CONTROLS and part.option in fields[method] and part.serves.startswith("the ")


class _ToyPart:
    """A part of ``cbf`` for the dynamics "toy" (one control, "push"), as a package of yours would write it."""

    serves, controls, option = "the toy", ("push",), None
    name = "toy"

    def __init__(self, **shared) -> None:
        self.shared = shared

    def check_spaces(self, observation_space, action_space) -> None:
        if action_space.dynamics_name != "toy":
            raise ValueError("not a toy")


def test_a_part_registered_in_the_process_is_served_under_the_method_and_named_in_refusals(monkeypatch):
    from rmm_guardians import parts

    monkeypatch.setattr(parts, "_REGISTERED", {})
    parts.register_part("cbf", "toy", _ToyPart)
    g = CBFGuardian()
    assert g.served() == ("dubins3d", "quadrotor", "toy")
    toy = GuardianActionSpace(("push",), [-1.0], [1.0], dynamics_name="toy")
    g.check_spaces(None, toy)
    delegate = g._delegate_for(toy)
    assert isinstance(delegate, _ToyPart) and delegate.name == "cbf" and set(delegate.shared) >= {"solver", "eps"}
    with pytest.raises(ValueError, match=r"and the quadrotor \(controls .*\) and the toy \(controls \('push',\)\)"):
        g.check_spaces(None, GuardianActionSpace(("a",), [-1.0], [1.0]))
    assert HJGuardian().served() == ("dubins3d", "quadrotor")  # another method's parts are its own
    with pytest.raises(ValueError, match="part must be a guardian class or 'module:Class'"):
        parts.register_part("cbf", "toy", "no colon")


def test_a_package_s_part_registers_through_the_entry_point_group(tmp_path, monkeypatch):
    from rmm_guardians.parts import parts_of

    (tmp_path / "toyparts.py").write_text("from tests.test_dispatch import _ToyPart as ToyHJ\n")
    info = tmp_path / "toyparts-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: toyparts\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[rmm_guardians.parts]\nhj.toy = toyparts:ToyHJ\nhj.broken = toyparts:Missing\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.warns(RuntimeWarning, match=r"hj.broken = 'toyparts:Missing' of 'toyparts' failed"):
        found = parts_of("hj")
    assert list(found) == ["dubins3d", "quadrotor", "toy"] and found["toy"] is _ToyPart
    with pytest.warns(RuntimeWarning):
        assert HJGuardian().served() == ("dubins3d", "quadrotor", "toy")
