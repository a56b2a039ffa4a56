"""Batched labels of a simulator of your own (its ``step_batch`` hook, run a tree level at a time
by :func:`rmm_envs.adapters.step_batch.batched_failed_ends`) are the step-by-step snapshot path's
labels bit for bit: every output of the estimator (risk, the minimum-risk control and its hold,
the leaf counts) for many tree sizes, seeds and horizons, with failures the step reports, failed
states, states that stop being finite, a ``failure`` of the user's, discrete actions, and a
``step_batch`` that writes into its input or returns an array it writes again."""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.adapters import SnapshotScene
from rmm_envs.risk import RiskEstimator

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "docs" / "examples"))
from own_simulator_rays import PointRays  # noqa: E402
from own_simulator_wall import CartWall  # noqa: E402


def _step_by_step(cls):
    return type(f"{cls.__name__}StepByStep", (cls,), {"step_batch": None})


def _bits(r) -> tuple[bytes, ...]:
    return tuple(
        np.ascontiguousarray(a).tobytes() + str(a.dtype).encode()
        for a in (r.risk, r.min_risk_ctrl, r.min_risk_ctrl_dur, r.n_leaves)
    )


def _both(cls, states, seed, failure=None, **kw):
    """The estimator's results batched and step by step, on the same tree of controls."""
    out = []
    for sim_cls in (cls, _step_by_step(cls)):
        scene = SnapshotScene(sim_cls(), failure=failure, default_horizon=cls.default_horizon)
        out.append(RiskEstimator(scene, **kw).estimate(states, np.random.default_rng(seed)))
    return out


class Slope:
    """A cart on a slope with a pit at x >= 1 (the step reports it), a cliff past x <= -1 (a failed
    state), and a speed that overflows to inf past |v| > 1e300 (a state that is not finite)."""

    dt = 0.05
    action_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float64)
    default_horizon = 0.2

    def __init__(self):
        self.s = np.zeros(2)

    def get_state(self):
        return self.s.copy()

    def set_state(self, s):
        self.s = np.array(s, dtype=float)

    def _next(self, x, v, a):
        v2 = v * 1e200 if abs(v) > 5.0 else v + self.dt * (a - 0.3 * np.sin(x))
        return x + self.dt * v2, v2

    def step(self, action):
        with np.errstate(over="ignore", invalid="ignore"):
            x, v = self._next(self.s[0], self.s[1], float(action[0]))
        self.s = np.array([x, v])
        return bool(x >= 1.0)

    def step_batch(self, states, actions):
        with np.errstate(over="ignore", invalid="ignore"):
            pairs = [self._next(x, v, a) for (x, v), a in zip(states.tolist(), actions[:, 0].tolist(), strict=True)]
        nxt = np.array(pairs, dtype=float).reshape(-1, 2)
        return nxt, nxt[:, 0] >= 1.0

    def state_failed(self, states):
        return np.asarray(states)[:, 0] <= -1.0


class Walker:
    """Discrete steps of -1, 0, +1 on a line; fails at |x| >= 3."""

    dt = 1.0
    action_space = gym.spaces.Discrete(3, start=-1)
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
        x = states[:, 0] + actions[:, 0]
        return x[:, None], np.abs(x) >= 3

    def state_failed(self, states):
        return np.abs(np.asarray(states)[:, 0]) >= 3


class InPlaceCartWall(CartWall):
    """``step_batch`` returns a buffer it keeps and writes again at its next call, and overwrites
    its input after reading it: handed its own buffer back, it would return -7s."""

    def step_batch(self, states, actions):
        buf = getattr(self, "_buf", None)
        if buf is None or buf.shape != states.shape:
            buf = self._buf = np.empty_like(states)
        a = actions[:, 0].astype(float)
        buf[:, 0] = states[:, 0] + self.dt * (states[:, 1] + 0.5 * self.dt * a)
        buf[:, 1] = states[:, 1] + self.dt * a
        states[:] = -7.0
        return buf, buf[:, 0] >= 2.0


class StrictCartWall(CartWall):
    """``step_batch`` refuses a state that failed: a branch leaves the batch at its first failure."""

    def step_batch(self, states, actions):
        assert not self.state_failed(states).any(), "a failed state was stepped on"
        return CartWall.step_batch(self, states, actions)


TREES = st.tuples(st.integers(1, 6), st.integers(0, 3)).filter(lambda t: t[0] ** t[1] <= 216)


@settings(max_examples=30, deadline=None)
@given(tree=TREES, steps=st.integers(1, 7), seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40))
def test_cart_wall_batched_is_step_by_step_bit_for_bit(tree, steps, seed, n):
    branches, depth = tree
    states = CartWall().sample_states(np.random.default_rng(seed), n)
    kw = dict(branches=branches, depth=depth, horizon=steps * CartWall.dt, n_steps=2 + steps % 4)
    batched, plain = _both(CartWall, states, seed, **kw)
    assert _bits(batched) == _bits(plain)


@settings(max_examples=20, deadline=None)
@given(tree=TREES, seed=st.integers(0, 2**32 - 1), metric=st.sampled_from(["expected", "cvar", "worst"]))
def test_failures_of_every_kind_and_a_users_failure_give_the_same_bits(tree, seed, metric):
    branches, depth = tree
    rng = np.random.default_rng(seed)
    states = np.column_stack([rng.uniform(-0.9, 0.95, 24), rng.uniform(-6.0, 6.0, 24)])
    kw = dict(branches=branches, depth=depth, horizon=0.2, metric=metric, alpha=0.4 if metric == "cvar" else None)
    batched, plain = _both(Slope, states, seed, failure=lambda s: np.abs(s[:, 1]) > 1e250, **kw)
    assert _bits(batched) == _bits(plain)


@pytest.mark.parametrize("fused", [True, False], ids=["fused", "paths"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_point_rays_and_a_discrete_walker_give_the_same_bits(seed, fused):
    states = PointRays().sample_states(np.random.default_rng(seed), 12)
    batched, plain = _both(PointRays, states, seed, branches=5, depth=2, horizon=0.5, fused=fused)
    assert _bits(batched) == _bits(plain) and 0 < batched.risk.mean() < 1
    walk = np.array([[0.0], [2.0], [-2.0], [1.0]])
    batched, plain = _both(Walker, walk, seed, branches=3, depth=3, horizon=2.0, fused=fused)
    assert _bits(batched) == _bits(plain)


@pytest.mark.parametrize("chunk", [1, 5, None])
def test_the_tutorials_size_and_any_chunking_give_the_same_bits(chunk):
    states = CartWall().sample_states(np.random.default_rng(11), 40)
    batched, plain = _both(StrictCartWall, states, 3, branches=32, depth=2, horizon=0.5, chunk_size=chunk)
    assert _bits(batched) == _bits(plain) and 0 < batched.risk.mean() < 1


def test_a_level_is_path_failed_of_the_paths_and_their_last_points():
    rng = np.random.default_rng(5)
    states = CartWall().sample_states(rng, 3000)
    controls = rng.uniform(-1, 1, (3000, 1))
    fast = SnapshotScene(CartWall(), default_horizon=0.5)
    slow = SnapshotScene(_step_by_step(CartWall)(), default_horizon=0.5)
    for horizon in (0.1, 0.3, 0.5, 1.2):
        failed, ends = fast.propagate_failed(states, controls, horizon, 8)
        paths = slow.propagate(states, controls, horizon, 8)
        assert np.array_equal(failed, slow.path_failed(paths)) and 0 < failed.mean() < 1
        assert ends[~failed].tobytes() == paths[~failed, -1].tobytes()
        assert np.array_equal(slow.propagate_failed(states, controls, horizon, 8)[0], failed)
    assert fast.propagate_failed(states[:0], controls[:0], 0.5, 8)[0].shape == (0,)


def test_candidates_and_a_step_batch_that_writes_into_its_arrays():
    states = CartWall().sample_states(np.random.default_rng(8), 30)
    before = states.copy()
    candidates = np.array([[-1.0], [0.0], [1.0]])
    risks = []
    for cls in (CartWall, InPlaceCartWall, _step_by_step(CartWall)):
        est = RiskEstimator(SnapshotScene(cls(), default_horizon=0.5), branches=6, depth=2, horizon=0.5)
        risks.append(_bits(est.estimate(states, np.random.default_rng(2))))
        risks.append(est.estimate_candidates(states, candidates, 0.3, np.random.default_rng(2)).tobytes())
    assert risks[0:2] == risks[2:4] == risks[4:6]
    assert np.array_equal(states, before)


def test_a_state_failed_of_the_wrong_shape_is_named_in_one_line():
    class Wrong(CartWall):
        def state_failed(self, states):
            return np.asarray(states)[:, :1] >= 2.0

    est = RiskEstimator(SnapshotScene(Wrong(), name="Wrong"), branches=4, depth=1, horizon=0.5)
    with pytest.raises(ValueError, match=r"Wrong: state_failed on 1 states must return shape \(1,\), got \(1, 1\)"):
        est.estimate(np.array([[0.0, 0.0]]), np.random.default_rng(0))
