"""The parallel-autonomy contract (rmm_envs.autonomy): action space, parsing, observation layout."""

from __future__ import annotations

import copy
import math
import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs import autonomy
from rmm_envs.autonomy import GuardianActionSpace, ObservationBox, ObservationLayout
from rmm_envs.systems.dubins4d.dynamics import Dubins4D

D4 = GuardianActionSpace.for_dynamics(Dubins4D(), ("turnrate_ctrl", "accel_ctrl"))


def test_dubins4d_space_is_the_plain_dict_it_replaced():
    plain = spaces.Dict(
        {
            "active_ctrl": spaces.Discrete(2),
            "turnrate_ctrl": spaces.Box(-0.25, 0.25, shape=(1,), dtype=np.float64),
            "accel_ctrl": spaces.Box(-0.5, 0.5, shape=(1,), dtype=np.float64),
        }
    )
    assert D4 == plain and list(D4.keys()) == list(plain.keys())
    # same seeding and sampling order, so seeded random actions are unchanged
    D4.seed(3), plain.seed(3)
    for _ in range(5):
        a, b = D4.sample(), plain.sample()
        assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert D4.controls == ("turnrate_ctrl", "accel_ctrl")
    assert D4.control_low.tolist() == [-0.25, -0.5] and D4.control_high.tolist() == [0.25, 0.5]
    assert gym.make("Dubins4DGuarded-v0").action_space == D4


def test_parse_clips_and_orders_the_control_vector():
    on, u = D4.parse({"active_ctrl": 1, "turnrate_ctrl": [9.0], "accel_ctrl": -0.1})
    assert on and u.tolist() == [0.25, -0.1]
    off, u = D4.parse(D4.inactive())
    assert not off and u.tolist() == [0.0, 0.0]
    assert autonomy.parse(D4.active([-1, 1]), D4)[1].tolist() == [-0.25, 0.5]
    assert autonomy.inactive(D4)["active_ctrl"] == 0 and autonomy.active(D4, [0.1, 0.2])["active_ctrl"] == 1


@settings(max_examples=60, deadline=None)
@given(st.floats(-0.25, 0.25, width=32), st.floats(-0.5, 0.5, width=32))
def test_active_then_parse_round_trips_inside_the_bounds(w, a):
    on, u = D4.parse(D4.active([w, a]))
    assert on and u.tolist() == [w, a]
    assert D4.contains(D4.active([w, a]))


@pytest.mark.parametrize(
    "action, msg",
    [
        ([1, 2, 3], "must be a dict"),
        ({"active_ctrl": 1, "turnrate_ctrl": 0.0}, "missing field 'accel_ctrl'"),
        ({"active_ctrl": 1, "turnrate_ctrl": 0.0, "accel_ctrl": 0.0, "brake": 1}, "unknown fields \\['brake'\\]"),
        ({"active_ctrl": 2, "turnrate_ctrl": 0.0, "accel_ctrl": 0.0}, "'active_ctrl' must be 0 or 1"),
        ({"active_ctrl": "1", "turnrate_ctrl": 0.0, "accel_ctrl": 0.0}, "'active_ctrl' must be 0 or 1"),
        ({"active_ctrl": 1, "turnrate_ctrl": np.nan, "accel_ctrl": 0.0}, "'turnrate_ctrl' must be finite"),
        ({"active_ctrl": 1, "turnrate_ctrl": 0.0, "accel_ctrl": [0.0, 1.0]}, "'accel_ctrl' must be a number"),
        ({"active_ctrl": 1, "turnrate_ctrl": "x", "accel_ctrl": 0.0}, "'turnrate_ctrl' must be a number"),
    ],
)
def test_parse_names_the_bad_field(action, msg):
    with pytest.raises(ValueError, match=msg):
        D4.parse(action)


def test_module_functions_refuse_a_space_without_the_contract():
    plain = spaces.Dict({"active_ctrl": spaces.Discrete(2)})
    for call in (
        lambda: autonomy.inactive(plain),
        lambda: autonomy.active(plain, [0]),
        lambda: autonomy.parse({}, plain),
    ):
        with pytest.raises(TypeError, match="GuardianActionSpace"):
            call()


@pytest.mark.parametrize(
    "controls, low, high, msg",
    [
        ((), [], [], "distinct non-empty"),
        (("a", "a"), [0, 0], [1, 1], "distinct"),
        (("active_ctrl",), [0], [1], "activation flag"),
        (("a", "b"), [0], [1, 1], "one bound per control"),
        (("a",), [1], [0], "low <= high"),
        (("a",), [-math.inf], [0], "finite"),
    ],
)
def test_space_refuses_bad_definitions(controls, low, high, msg):
    with pytest.raises(ValueError, match=msg):
        GuardianActionSpace(controls, low, high)


def test_active_needs_one_value_per_control():
    with pytest.raises(ValueError, match="one value per control"):
        D4.active([0.1])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 1), st.floats(-2, 2), st.floats(-2, 2)), min_size=1, max_size=6))
def test_batch_parse_agrees_with_single_parse(rows):
    n = len(rows)
    batch = {
        "active_ctrl": np.array([r[0] for r in rows]),
        "turnrate_ctrl": np.array([[r[1]] for r in rows]),
        "accel_ctrl": np.array([r[2] for r in rows]),
    }
    act, ctrl = D4.parse_batch(batch, n)
    for i, (f, w, a) in enumerate(rows):
        on, u = D4.parse({"active_ctrl": f, "turnrate_ctrl": w, "accel_ctrl": a})
        assert act[i] == on and ctrl[i].tolist() == u.tolist()


def test_batch_parse_names_field_and_sub_env():
    good = {"active_ctrl": np.zeros(3), "turnrate_ctrl": np.zeros(3), "accel_ctrl": np.zeros(3)}
    with pytest.raises(ValueError, match="'accel_ctrl' of sub-env 1 must be finite"):
        D4.parse_batch({**good, "accel_ctrl": np.array([0.0, np.inf, 0.0])}, 3)
    with pytest.raises(ValueError, match="'active_ctrl' of sub-env 2 must be 0 or 1"):
        D4.parse_batch({**good, "active_ctrl": np.array([0, 1, 3])}, 3)
    with pytest.raises(ValueError, match="must be 3 numbers"):
        D4.parse_batch({**good, "turnrate_ctrl": np.zeros(2)}, 3)


def test_spaces_survive_pickle_and_deepcopy():
    env = gym.make("Dubins4DGuarded-v0")
    for space in (env.action_space, env.observation_space):
        for clone in (pickle.loads(pickle.dumps(space)), copy.deepcopy(space)):
            assert clone == space and type(clone) is type(space)
    assert pickle.loads(pickle.dumps(env.action_space)).controls == ("turnrate_ctrl", "accel_ctrl")
    assert pickle.loads(pickle.dumps(env.observation_space)).layout == env.observation_space.layout


def test_dubins4d_observation_layout_matches_the_observation():
    env = gym.make("Dubins4DGuarded-v0", n_rays=8).unwrapped
    obs, _ = env.reset(
        seed=1, options={"state": [1.0, 2.0, 0.5, 1.5], "goal": [4.0, -2.0, 0.5], "obstacles": [[-5.0, -5.0, 2.0]]}
    )
    lay = autonomy.layout(env.observation_space)
    assert lay.size == 13 and lay.names == ("time", "goal_offset", "heading", "speed", "rays")
    assert obs[lay["goal_offset"]].tolist() == [3.0, -4.0]
    assert obs[lay.index("heading")] == np.float32(0.5) and obs[lay.index("speed")] == np.float32(1.5)
    assert lay["rays"] == slice(5, 13)
    assert lay.ray_index(0.0) == 5 and lay.ray_index(math.pi / 2) == 7 and lay.ray_index(-math.pi / 4) == 12
    assert lay.ray_index(math.pi) == 9


def test_layout_errors_name_what_is_wrong():
    lay = ObservationLayout.of(("time", 1), ("speed", 1))
    with pytest.raises(KeyError, match="no field 'rays'"):
        lay["rays"]
    with pytest.raises(KeyError, match="no rays"):
        lay.ray_index(0.0)
    with pytest.raises(ValueError, match="not one"):
        ObservationLayout.of(("goal", 2)).index("goal")
    with pytest.raises(ValueError, match="contiguous"):
        ObservationLayout((("a", 0, 1), ("b", 2, 3)))
    with pytest.raises(ValueError, match="one angle per ray"):
        ObservationLayout.of(("rays", 3), ray_angles=[0.0])
    with pytest.raises(ValueError, match="shape"):
        ObservationBox(np.zeros(3, np.float32), np.ones(3, np.float32), lay)
    with pytest.raises(TypeError, match="carries no layout"):
        autonomy.layout(spaces.Box(0, 1, (2,)))
