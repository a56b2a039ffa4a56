import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.envs.dubins4d import Dubins4DCirclesEnv
from rmm_envs.scenes import Dubins4DScene
from rmm_envs.risk import RiskEstimator, check_scene, cvar, get_metric, worst_case
from tests.toy_systems import Line1D


def ctl(*levels):
    return [np.asarray(level, float)[None, :, None] for level in levels]


def test_one_of_three_failing_at_depth_one_gives_a_third():
    est = RiskEstimator(Line1D(), branches=3, depth=1, horizon=1.0, n_steps=2)
    r = est.estimate(np.zeros((1, 1)), controls=ctl([0.2, 0.5, 2.0]))
    assert r.risk[0] == pytest.approx(1 / 3)
    assert r.min_risk_ctrl[0, 0] == 0.2  # first of the tied minimum-risk children
    assert r.min_risk_ctrl_dur[0] == 1.0
    assert r.n_leaves[0] == 3


def test_all_free_and_all_failing():
    est = RiskEstimator(Line1D(), branches=3, depth=1, horizon=1.0, n_steps=2)
    assert est.estimate(np.zeros((1, 1)), controls=ctl([0.1, 0.2, 0.3])).risk[0] == 0.0
    assert est.estimate(np.zeros((1, 1)), controls=ctl([1.5, 2.0, 3.0])).risk[0] == 1.0


def test_depth_two_by_hand():
    # level 1: x -> 0.1, 0.5, 1.2 (fails).  level 2 children (2 per node, t = 1):
    # node 0 (x=0.1): +0.2 -> 0.3 ok, +0.95 -> 1.05 fail  => 1/2
    # node 1 (x=0.5): +0.1 -> ok, +0.2 -> ok               => 0
    # node 2 failed: 1, its children ignored
    est = RiskEstimator(Line1D(), branches=2, depth=2, horizon=1.0, n_steps=2)
    with pytest.raises(ValueError):  # 2 branches, 3 controls
        est.estimate(np.zeros((1, 1)), controls=ctl([0.1, 0.5, 1.2], [0.2] * 6))
    est = RiskEstimator(Line1D(), branches=3, depth=2, horizon=1.0, n_steps=2)
    lvl2 = [0.2, 0.95, 0.0, 0.1, 0.2, 0.0, 3.0, 3.0, 3.0]
    r = est.estimate(np.zeros((1, 1)), controls=ctl([0.1, 0.5, 1.2], lvl2))
    node0 = 1 / 3  # children of x=0.1: 0.3 ok, 1.05 fail, 0.1 ok
    node1 = 0.0
    assert r.risk[0] == pytest.approx((node0 + node1 + 1.0) / 3)
    assert r.min_risk_ctrl[0, 0] == 0.5
    # terminal nodes: the failed level-1 node + 6 leaves under the live ones
    assert r.n_leaves[0] == 7


def test_worst_case_and_cvar_metrics_on_a_tree():
    kw = dict(branches=4, depth=1, horizon=1.0, n_steps=2)
    c = ctl([0.1, 2.0, 0.3, 0.4])  # one of four fails
    assert RiskEstimator(Line1D(), metric="worst", **kw).estimate(np.zeros((1, 1)), controls=c).risk[0] == 1.0
    assert RiskEstimator(Line1D(), metric="cvar", alpha=0.25, **kw).estimate(np.zeros((1, 1)), controls=c).risk[0] == 1.0
    assert RiskEstimator(Line1D(), metric="cvar", alpha=0.5, **kw).estimate(np.zeros((1, 1)), controls=c).risk[0] == pytest.approx(0.5)


def test_metric_values():
    v = np.array([[0.0, 0.0, 1.0, 1.0], [0.0, 0.2, 0.4, 0.6]])
    np.testing.assert_allclose(cvar(v, 0.5), [1.0, 0.5])
    np.testing.assert_allclose(cvar(v, 0.75), [2 / 3, (0.6 + 0.4 + 0.2) / 3])
    np.testing.assert_allclose(cvar(v, 0.125), [1.0, 0.6])  # inside the worst child
    np.testing.assert_allclose(worst_case(v), [1.0, 0.6])
    np.testing.assert_allclose(get_metric("expected")(v), [0.5, 0.3])


@given(st.lists(st.floats(0, 1), min_size=1, max_size=40), st.floats(0.01, 0.99))
def test_cvar_lies_between_mean_and_max(values, alpha):
    v = np.array(values)
    c = cvar(v, alpha)
    assert v.mean() - 1e-12 <= c <= v.max() + 1e-12


def test_root_in_collision_is_one_without_expansion():
    est = RiskEstimator(Line1D(), branches=5, depth=2, horizon=1.0, n_steps=2)
    r = est.estimate(np.array([[1.5], [0.0]]), rng=np.random.default_rng(0))
    assert r.risk[0] == 1.0 and r.n_leaves[0] == 0 and r.min_risk_ctrl_dur[0] == 0.0


def test_depth_zero_is_the_failure_indicator_or_heuristic():
    assert RiskEstimator(Line1D(), depth=0).estimate(np.array([[0.0], [2.0]])).risk.tolist() == [0.0, 1.0]
    r = RiskEstimator(Line1D(), depth=0, leaf="heuristic").estimate(np.array([[0.0], [2.0]]))
    assert r.risk.tolist() == [0.5, 1.0]


def test_leaf_heuristic_used_at_non_failed_leaves():
    est = RiskEstimator(Line1D(), branches=2, depth=1, horizon=1.0, n_steps=2, leaf="heuristic")
    assert est.estimate(np.zeros((1, 1)), controls=ctl([0.1, 2.0])).risk[0] == pytest.approx(0.75)


def scene(obstacles, goal=(50.0, 50.0, 1.0)):
    return Dubins4DScene(np.asarray(obstacles, float), np.asarray(goal, float))


def test_far_obstacles_give_exactly_zero():
    sc = scene([[60.0, 0.0, 2.0], [-40.0, 30.0, 5.0]])
    r = RiskEstimator(sc).estimate(np.array([[0.0, 0.0, 0.3, 2.0], [1.0, 1.0, -2.0, 0.0]]), np.random.default_rng(0))
    assert r.risk.tolist() == [0.0, 0.0]
    assert r.n_leaves.tolist() == [1024, 1024]


def test_fast_into_a_close_obstacle_gives_one():
    # 0.5 m from a wall at 2 m/s: stopping takes 4 m, turning away takes far longer
    sc = scene([[1.5, 0.0, 1.0]])
    r = RiskEstimator(sc).estimate(np.array([[0.0, 0.0, 0.0, 2.0]]), np.random.default_rng(0))
    assert r.risk[0] == 1.0
    assert r.n_leaves[0] == 32  # every first-level branch failed


def test_dubins4d_leaf_heuristic_values():
    # the leaf heuristic's hand-computed examples (docs/original-code.md item 24): v=1, forward ray 4 -> 0.25; v=2, ray 10 -> 0.4; v=0.5, ray 1 -> 0.25
    sc = scene([[5.0, 0.0, 1.0], [20.0, 20.0, 1.0]])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[0.0, 0.0, 0.0, 1.0]])), [0.25])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[-6.0, 0.0, 0.0, 2.0]])), [0.4])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[3.0, 0.0, 0.0, 0.5]])), [0.25])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[3.0, 0.0, 0.0, 0.0]])), [0.0])  # no assert crash


def _recursive(system, state, ctrl_tree, n, m, t, n_steps, reduce, path=None):
    """Algorithm 1 written literally: one branch at a time, recursion on children."""
    if system.state_failed(state[None])[0] or (path is not None and system.path_failed(path[None])[0]):
        return 1.0
    if m == 0:
        return 0.0
    vals = []
    for i in range(n):
        u, sub = ctrl_tree[i]
        p = system.propagate(state[None], u[None], t, n_steps)[0]
        vals.append(_recursive(system, p[-1], sub, n, m - 1, t, n_steps, reduce, p))
    return float(reduce(np.array(vals)))


def _tree_from_levels(levels, root, n, m):
    """Nest the per-level control arrays (root-major) into a recursive tree for one root."""
    def build(lvl, idx):
        if lvl == m:
            return None
        return [(levels[lvl][root, idx * n + i], build(lvl + 1, idx * n + i)) for i in range(n)]
    return build(0, 0)


@pytest.mark.parametrize("metric, alpha", [("expected", None), ("cvar", 0.3), ("worst", None)])
def test_batched_agrees_with_recursive_reference(metric, alpha):
    env = Dubins4DCirclesEnv()
    env.reset(seed=4)
    sc = env.risk_scene()
    rng = np.random.default_rng(1)
    states = env.sample_states(rng, 12)
    n, m = 5, 3
    est = RiskEstimator(sc, branches=n, depth=m, horizon=1.5, n_steps=6, metric=metric, alpha=alpha, chunk_size=5)
    levels = est.draw_controls(rng, len(states))
    batched = est.estimate(states, controls=levels)
    for b in range(len(states)):
        ref = _recursive(sc, states[b], _tree_from_levels(levels, b, n, m), n, m, 1.5, 6, est.reduce)
        assert batched.risk[b] == pytest.approx(ref, abs=1e-12)


def test_deterministic_and_independent_of_chunking():
    env = Dubins4DCirclesEnv()
    env.reset(seed=2)
    states = env.sample_states(np.random.default_rng(0), 40)
    a = RiskEstimator(env.risk_scene(), chunk_size=7).estimate(states, np.random.default_rng(9))
    b = RiskEstimator(env.risk_scene(), chunk_size=40).estimate(states, np.random.default_rng(9))
    np.testing.assert_array_equal(a.risk, b.risk)
    np.testing.assert_array_equal(a.min_risk_ctrl, b.min_risk_ctrl)
    c = RiskEstimator(env.risk_scene()).estimate(states, np.random.default_rng(10))
    assert not np.array_equal(a.risk, c.risk)


def test_custom_policy_is_called_with_parent_states():
    calls = []

    def always_stop(states, rng):
        calls.append(states.shape)
        return np.zeros((states.shape[0], 1))

    r = RiskEstimator(Line1D(), branches=4, depth=2, policy=always_stop).estimate(np.zeros((3, 1)), np.random.default_rng(0))
    assert r.risk.tolist() == [0.0, 0.0, 0.0]
    assert calls == [(12, 1), (48, 1)]


def test_sampled_branches_obey_speed_limits():
    sc = scene([[60.0, 0.0, 1.0]])
    rng = np.random.default_rng(0)
    states = np.c_[np.zeros((500, 3)), rng.uniform(0, 2, 500)]
    paths = sc.propagate(states, sc.sample_controls(rng, 500), 4.0, 9)
    assert paths[..., 3].min() >= 0.0 and paths[..., 3].max() <= 2.0


@pytest.mark.parametrize(
    "kwargs, match",
    [({"branches": 0}, "branches"), ({"depth": -1}, "depth"), ({"horizon": 0}, "horizon"),
     ({"horizon": float("nan")}, "horizon"), ({"n_steps": 1}, "n_steps"), ({"metric": "median"}, "metric"),
     ({"metric": "cvar"}, "alpha"), ({"metric": "cvar", "alpha": 1.0}, "alpha"), ({"metric": "cvar", "alpha": 0.0}, "alpha"),
     ({"leaf": "one"}, "leaf")],
)
def test_bad_parameters(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RiskEstimator(Line1D(), **kwargs)


def test_bad_systems_and_states():
    with pytest.raises(TypeError, match="lacks"):
        RiskEstimator(object())
    with pytest.raises(TypeError, match="lacks"):
        check_scene(np.zeros(3))
    est = RiskEstimator(Line1D(), branches=2, depth=1)
    with pytest.raises(ValueError, match="shape"):
        est.estimate(np.zeros((2, 3)), np.random.default_rng(0))
    with pytest.raises(ValueError, match="finite"):
        est.estimate(np.array([[np.nan]]), np.random.default_rng(0))
    with pytest.raises(ValueError, match="rng"):
        est.estimate(np.zeros((1, 1)))
