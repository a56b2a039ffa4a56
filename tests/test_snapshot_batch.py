"""A simulator of your own labelled batched (its ``step_batch`` hook): the same labels, bit for bit,
as the step-by-step snapshot path, and a hook that answers wrongly is named in one line."""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.adapters import SnapshotScene
from rmm_envs.envs.any_env import SIMULATOR_HOOKS, hooks_table
from rmm_envs.risk import RiskEstimator

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "docs" / "examples"))
from own_simulator_rays import PointRays  # noqa: E402
from own_simulator_wall import CartWall  # noqa: E402


def _step_by_step(cls):
    return type(f"{cls.__name__}StepByStep", (cls,), {"step_batch": None})


def _labels(cls, states, seed, **kw):
    scene = SnapshotScene(cls(), default_horizon=cls.default_horizon)
    est = RiskEstimator(scene, branches=kw.get("branches", 8), depth=kw.get("depth", 2), horizon=cls.default_horizon)
    r = est.estimate(states, np.random.default_rng(seed))
    return r.risk, r.n_leaves


@pytest.mark.parametrize("cls", [CartWall, PointRays], ids=["CartWall", "PointRays"])
def test_batched_labels_are_the_step_by_step_labels_bit_for_bit(cls):
    sim = cls()
    states = np.asarray(sim.sample_states(np.random.default_rng(3), 48), dtype=float)
    batched = _labels(cls, states, 7)
    plain = _labels(_step_by_step(cls), states, 7)
    assert batched[0].tobytes() == plain[0].tobytes() and np.array_equal(batched[1], plain[1])
    assert 0 < batched[0].mean() < 1  # some states are safe, some doomed: the test compares something


@settings(max_examples=25, deadline=None)
@given(x=st.floats(-0.5, 1.99), v=st.floats(-2.5, 2.5), seed=st.integers(0, 2**31))
def test_cart_wall_paths_agree_state_by_state(x, v, seed):
    """The paths themselves (every point, NaN after the first failure), not only the labels."""
    controls = np.random.default_rng(seed).uniform(-1, 1, (16, 1))
    states = np.repeat([[x, v]], 16, axis=0)
    a = SnapshotScene(CartWall(), default_horizon=0.5).propagate(states, controls, 0.5, 6)
    b = SnapshotScene(_step_by_step(CartWall)(), default_horizon=0.5).propagate(states, controls, 0.5, 6)
    assert a.tobytes() == b.tobytes()


def test_a_discrete_simulator_is_batched_with_integer_actions():
    class Walker:
        dt = 1.0
        action_space = gym.spaces.Discrete(3, start=-1)  # step -1, 0 or +1
        default_horizon = 2.0

        def __init__(self):
            self.x = 0.0

        def get_state(self):
            return np.array([self.x])

        def set_state(self, s):
            self.x = float(s[0])

        def step(self, a):
            self.x += a
            return abs(self.x) >= 3

        def step_batch(self, states, actions):
            assert actions.dtype == np.int64 and actions.shape == (len(states), 1)
            x = states[:, 0] + actions[:, 0]
            return x[:, None], np.abs(x) >= 3

        def state_failed(self, states):
            return np.abs(np.asarray(states)[:, 0]) >= 3

    states = np.array([[0.0], [2.0], [-2.0]])
    assert _labels(Walker, states, 1)[0].tobytes() == _labels(_step_by_step(Walker), states, 1)[0].tobytes()


@pytest.mark.parametrize(
    ("answer", "words"),
    [
        (lambda s, a: s, "must return (states (N, d), failed (N,) bool), got ndarray"),
        (lambda s, a: (s[:1], np.zeros(len(s), bool)), "must return shapes"),
        (lambda s, a: (s, np.zeros((len(s), 2), bool)), "must return shapes"),
    ],
    ids=["not-a-pair", "too-few-states", "failed-2d"],
)
def test_a_wrong_step_batch_is_named_in_one_line(answer, words):
    class Wrong(CartWall):
        def step_batch(self, states, actions):
            return answer(states, actions)

    est = RiskEstimator(SnapshotScene(Wrong(), name="Wrong"), branches=4, depth=1, horizon=0.5)
    with pytest.raises((TypeError, ValueError), match="Wrong: step_batch") as e:
        est.estimate(np.array([[0.0, 0.0]]), np.random.default_rng(0))
    assert words in str(e.value) and "\n" not in str(e.value)


def test_the_hook_is_in_the_tutorials_table():
    hook = SIMULATOR_HOOKS["step_batch"]
    assert "rmm-datagen" in hook.needed_by and hook.default is not None
    assert "`step_batch`" in hooks_table()
