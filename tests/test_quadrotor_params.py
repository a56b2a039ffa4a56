"""One source per quadrotor fact: the URDF, PyBullet and the numpy propagator agree with QUADROTOR."""

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from rmm_envs.systems.quadrotor import room_collision
from rmm_envs.systems.quadrotor.body import QUADROTOR, Quadrotor, QuadrotorParams
from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv
from rmm_envs.systems.quadrotor.pybullet_body import urdf_path as _urdf_path


def test_urdf_agrees_with_the_parameter_object_exactly():
    link = ET.parse(_urdf_path()).getroot().find("link")
    inertial = link.find("inertial")
    assert float(inertial.find("mass").get("value")) == QUADROTOR.mass
    inertia = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
    assert (inertia["ixx"], inertia["iyy"], inertia["izz"]) == QUADROTOR.inertia
    assert inertia["ixy"] == inertia["ixz"] == inertia["iyz"] == 0.0  # principal axes = body axes
    assert inertial.find("origin").get("xyz").split() == ["0", "0", "0"]  # centre of mass at the body origin
    for part in ("collision", "visual"):
        cyl = link.find(part).find("geometry").find("cylinder")
        assert float(cyl.get("radius")) == QUADROTOR.collision_radius
        assert float(cyl.get("length")) == QUADROTOR.collision_length


def test_the_env_configures_pybullet_from_the_parameter_object():
    env = QuadrotorRoomEnv(linear_damping=0.1, angular_damping=0.2)
    try:
        env.reset(seed=0)
        p, c = env.p, env.client
        info = p.getDynamicsInfo(env.body, -1, physicsClientId=c)
        assert info[0] == QUADROTOR.mass and info[2] == QUADROTOR.inertia
        engine = p.getPhysicsEngineParameters(physicsClientId=c)
        assert engine["fixedTimeStep"] == QUADROTOR.dt
        assert (engine["gravityAccelerationX"], engine["gravityAccelerationY"], engine["gravityAccelerationZ"]) == (
            0,
            0,
            -QUADROTOR.gravity,
        )
        np.testing.assert_array_equal(env.action_space.low, np.float32(QUADROTOR.control_low))
        np.testing.assert_array_equal(env.action_space.high, np.float32(QUADROTOR.control_high))
        # the env's damping arguments replace the defaults in its parameters, and the
        # labeller's propagator uses exactly those parameters
        assert env.params == dataclasses.replace(QUADROTOR, linear_damping=0.1, angular_damping=0.2)
        assert env.risk_scene().dynamics.params is env.params
    finally:
        env.close()
    assert QuadrotorRoomEnv().params == QUADROTOR


def test_defaults_and_derived_values():
    assert QUADROTOR == QuadrotorParams()
    assert QUADROTOR.hover_thrust == 4.905
    assert QUADROTOR.dt == 1 / 240
    assert (room_collision.RADIUS, room_collision.HALF) == (0.3, 0.05)
    quad = Quadrotor()
    assert quad.params is QUADROTOR
    np.testing.assert_array_equal(quad.control_low, [0, -2, -2, -1])
    np.testing.assert_array_equal(quad.control_high, [8, 2, 2, 1])
    assert quad.control_low.dtype == np.float64


def test_the_propagator_reads_its_parameters():
    s = np.array([[1.0, 2.0, 3.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]])
    heavy = Quadrotor(QuadrotorParams(mass=0.75))
    u = np.array([[heavy.params.hover_thrust, 0, 0, 0]])  # 7.36 N holds 0.75 kg ...
    np.testing.assert_allclose(heavy.propagate(s, u, 1.0, 4)[0, -1], s[0], atol=1e-12)
    climb = Quadrotor().propagate(s, u, 1.0, 4)[0, -1]  # ... and lifts 0.5 kg (9.81 / 2 m/s^2, less damping)
    assert climb[2] > 5.0 and 4.0 < climb[9] < 4.905
    undamped = Quadrotor(QuadrotorParams(linear_damping=0.0, angular_damping=0.0)).propagate(s, u, 1.0, 4)[0, -1]
    assert undamped[9] == pytest.approx(u[0, 0] / 0.5 - 9.81, rel=1e-12)  # v = a t exactly (semi-implicit Euler)
    # a coarser step: the same 1 s branch takes fewer, longer steps (3 x 10 instead of 3 x 80)
    coarse = Quadrotor(QuadrotorParams(dt=1 / 30)).propagate(s, u, 1.0, 4)[0, -1]
    assert not np.array_equal(coarse, climb) and coarse[9] == pytest.approx(climb[9], rel=0.02)
    # the control box clips
    wide = Quadrotor(QuadrotorParams(control_high=(20.0, 2.0, 2.0, 1.0)))
    big = np.array([[20.0, 0, 0, 0]])
    assert wide.propagate(s, big, 1.0, 2)[0, -1, 9] > Quadrotor().propagate(s, big, 1.0, 2)[0, -1, 9]


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("mass", 0.0, "mass must be a finite number > 0"),
        ("mass", float("nan"), "mass must be"),
        ("mass", True, "mass must be"),
        ("dt", -1 / 240, "dt must be a finite number > 0"),
        ("collision_radius", float("inf"), "collision_radius"),
        ("gravity", -9.81, "gravity must be a finite number >= 0"),
        ("linear_damping", -0.1, "linear_damping must be a finite number >= 0"),
        ("angular_damping", "0.04", "angular_damping"),
        ("inertia", (0.1, 0.1), "inertia must be 3 finite numbers"),
        ("inertia", (0.1, 0.0, 0.1), "inertia must be 3 principal moments > 0"),
        ("inertia", "abc", "inertia must be 3 finite numbers"),
        ("control_low", (0.0, -2.0, -2.0, float("nan")), "control_low must be 4 finite numbers"),
        ("control_high", (8.0, 2.0, -3.0, 1.0), "must be <= control_high"),
    ],
)
def test_bad_parameters_are_refused_by_name(field, value, match):
    with pytest.raises(ValueError, match=match):
        QuadrotorParams(**{field: value})


def test_parameters_are_frozen_and_normalised():
    with pytest.raises(dataclasses.FrozenInstanceError):
        QUADROTOR.mass = 1.0
    q = QuadrotorParams(inertia=np.array([1, 2, 3]), control_low=[0, -1, -1, -1])
    assert q.inertia == (1.0, 2.0, 3.0) and q.control_low == (0.0, -1.0, -1.0, -1.0)
    assert hash(q) == hash(QuadrotorParams(inertia=(1.0, 2.0, 3.0), control_low=(0.0, -1.0, -1.0, -1.0)))
    with pytest.raises(TypeError, match="QuadrotorParams"):
        Quadrotor(params={"mass": 0.5})
