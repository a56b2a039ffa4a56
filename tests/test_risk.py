import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rmm_envs.risk import RiskEstimator, check_scene, cvar, get_metric, worst_case
from rmm_envs.systems.dubins4d.env import Dubins4DGuardedEnv
from rmm_envs.systems.dubins4d.scene import Dubins4DScene
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
    assert (
        RiskEstimator(Line1D(), metric="cvar", alpha=0.25, **kw).estimate(np.zeros((1, 1)), controls=c).risk[0] == 1.0
    )
    assert RiskEstimator(Line1D(), metric="cvar", alpha=0.5, **kw).estimate(np.zeros((1, 1)), controls=c).risk[
        0
    ] == pytest.approx(0.5)


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
    # the leaf heuristic's hand-computed examples (docs/original-code.md item 24):
    # v=1, forward ray 4 -> 0.25; v=2, ray 10 -> 0.4; v=0.5, ray 1 -> 0.25
    sc = scene([[5.0, 0.0, 1.0], [20.0, 20.0, 1.0]])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[0.0, 0.0, 0.0, 1.0]])), [0.25])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[-6.0, 0.0, 0.0, 2.0]])), [0.4])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[3.0, 0.0, 0.0, 0.5]])), [0.25])
    np.testing.assert_allclose(sc.leaf_estimate(np.array([[3.0, 0.0, 0.0, 0.0]])), [0.0])  # no assert crash


def _recursive(scene, state, ctrl_tree, n, m, t, n_steps, reduce, path=None):
    """Algorithm 1 written literally: one branch at a time, recursion on children."""
    if scene.state_failed(state[None])[0] or (path is not None and scene.path_failed(path[None])[0]):
        return 1.0
    if m == 0:
        return 0.0
    vals = []
    for i in range(n):
        u, sub = ctrl_tree[i]
        p = scene.propagate(state[None], u[None], t, n_steps)[0]
        vals.append(_recursive(scene, p[-1], sub, n, m - 1, t, n_steps, reduce, p))
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
    env = Dubins4DGuardedEnv()
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
    env = Dubins4DGuardedEnv()
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

    r = RiskEstimator(Line1D(), branches=4, depth=2, policy=always_stop).estimate(
        np.zeros((3, 1)), np.random.default_rng(0)
    )
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
    [
        ({"branches": 0}, "branches"),
        ({"depth": -1}, "depth"),
        ({"horizon": 0}, "horizon"),
        ({"horizon": float("nan")}, "horizon"),
        ({"n_steps": 1}, "n_steps"),
        ({"metric": "median"}, "metric"),
        ({"metric": "cvar"}, "alpha"),
        ({"metric": "cvar", "alpha": 1.0}, "alpha"),
        ({"metric": "cvar", "alpha": 0.0}, "alpha"),
        ({"leaf": "one"}, "leaf"),
    ],
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


# ------------------------------------------------------------------ pinned where the tests above leave room
class IntFlagsLine1D(Line1D):
    """Line1D reporting failures as 0/1 integers and its control box as integer lists."""

    def __init__(self):
        super().__init__()
        self.control_low, self.control_high = [0], [3]

    def path_failed(self, paths):
        return super().path_failed(paths).astype(int)

    def state_failed(self, states):
        return super().state_failed(states).astype(int)


def test_failure_flags_given_as_integers_give_the_same_labels():
    states = np.array([[0.0], [0.5], [1.5], [0.9]])
    for kw in (dict(branches=3, depth=2), dict(branches=2, depth=1, leaf="heuristic"), dict(depth=0)):
        a = RiskEstimator(Line1D(), horizon=0.5, n_steps=3, **kw).estimate(states, np.random.default_rng(4))
        b = RiskEstimator(IntFlagsLine1D(), horizon=0.5, n_steps=3, **kw).estimate(states, np.random.default_rng(4))
        for f in ("risk", "min_risk_ctrl", "min_risk_ctrl_dur", "n_leaves"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    c = [[0.0], [0.6], [2.0]]
    est = RiskEstimator(IntFlagsLine1D(), branches=2, depth=0, horizon=1.0, n_steps=5)
    np.testing.assert_array_equal(
        est.estimate_candidates(states[:3], c, hold=1.0, rng=np.random.default_rng(0)),
        [[0, 0, 1], [0, 1, 1], [1, 1, 1]],
    )


def test_candidates_by_hand_b_differs_from_k_and_the_tree_runs_from_the_branch_end():
    """Line1D (x' = u, wall at 1): holding u for ``hold`` ends at x + u * hold; from there one level
    of 2 branches of t = 1 s with controls drawn from the rng fails where x_end + u' >= 1."""
    est = RiskEstimator(Line1D(), branches=2, depth=1, horizon=1.0, n_steps=3)
    states = np.array([[0.0], [0.25]])
    cands = [[0.0], [0.5], [2.0]]  # held 0.5 s: ends at x, x + 0.25, x + 1 (fails on the way for both roots)
    r = est.estimate_candidates(states, cands, hold=0.5, rng=np.random.default_rng(3))
    assert r.shape == (2, 3)
    # the tree's controls, drawn for the live ends in root-major, candidate-minor order (4 ends)
    u = np.random.default_rng(3).uniform(0.0, 3.0, size=(4, 2, 1))[..., 0]
    ends = np.array([0.0, 0.25, 0.25, 0.5])
    expected = (ends[:, None] + u >= 1.0).mean(axis=1)
    np.testing.assert_array_equal(r, [[expected[0], expected[1], 1.0], [expected[2], expected[3], 1.0]])


def test_candidates_refused_with_their_messages():
    est = RiskEstimator(IntFlagsLine1D(), branches=2, depth=1)
    rng = np.random.default_rng(0)
    cases = [
        (dict(states=np.zeros((1, 2)), candidates=[[0.0]], hold=1.0), "states must have shape (B, 1), got (1, 2)"),
        (dict(states=np.zeros(1), candidates=[[0.0]], hold=1.0), "states must have shape (B, 1), got (1,)"),
        (dict(states=np.zeros((1, 1)), candidates=[0.0], hold=1.0), "candidates must have shape (K >= 1, 1), got (1,)"),
        (
            dict(states=np.zeros((1, 1)), candidates=[[[0.0]]], hold=1.0),
            "candidates must have shape (K >= 1, 1), got (1, 1, 1)",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=np.zeros((0, 1)), hold=1.0),
            "candidates must have shape (K >= 1, 1), got (0, 1)",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=[[0.0, 1.0]], hold=1.0),
            "candidates must have shape (K >= 1, 1), got (1, 2)",
        ),
        (dict(states=np.zeros((1, 1)), candidates=[[np.inf]], hold=1.0), "candidates must be finite, got [[inf]]"),
        (
            dict(states=np.zeros((1, 1)), candidates=[[3.5]], hold=1.0),
            "candidates [[3.5]] fall outside the control box [[0.0], [3.0]]",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=[[-0.5]], hold=1.0),
            "candidates [[-0.5]] fall outside the control box [[0.0], [3.0]]",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=[[1.0]], hold=-1.0),
            "hold must be a finite number of seconds > 0, got -1.0",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=[[1.0]], hold="1"),
            "hold must be a finite number of seconds > 0, got '1'",
        ),
        (
            dict(states=np.zeros((1, 1)), candidates=[[1.0]], hold=np.nan),
            "hold must be a finite number of seconds > 0, got nan",
        ),
    ]
    cases.append(
        (
            dict(states=np.zeros((1, 1)), candidates=[[1.0]], hold=0.0),
            "hold must be a finite number of seconds > 0, got 0.0",
        )
    )
    for kw, text in cases:
        with pytest.raises(ValueError) as e:
            est.estimate_candidates(rng=rng, **kw)
        assert str(e.value) == text
    # the box's edges are inside it
    assert est.estimate_candidates(np.zeros((1, 1)), [[0.0], [3.0]], hold=0.1, rng=rng).shape == (1, 2)


def test_a_custom_policy_is_called_per_chunk_with_the_generator():
    """Four roots at x = 0 in chunks of two, one level of 4 branches, t = 1: the policy draws from
    the generator it is given, once per chunk; a root's risk is the share of its draws >= 1."""
    calls = []

    def draw(states, rng):
        calls.append(states.shape[0])
        return rng.uniform(0.0, 3.0, size=(states.shape[0], 1))

    est = RiskEstimator(Line1D(), branches=4, depth=1, horizon=1.0, n_steps=2, policy=draw, chunk_size=2)
    r = est.estimate(np.zeros((4, 1)), np.random.default_rng(5))
    ref = np.random.default_rng(5)
    u = np.concatenate([ref.uniform(0.0, 3.0, size=(8, 1)), ref.uniform(0.0, 3.0, size=(8, 1))])[:, 0].reshape(4, 4)
    assert calls == [8, 8]
    np.testing.assert_array_equal(r.risk, (u >= 1.0).mean(axis=1))
    np.testing.assert_array_equal(r.min_risk_ctrl[:, 0], u[np.arange(4), np.argmin(u >= 1.0, axis=1)])
    with pytest.raises(ValueError) as e:
        RiskEstimator(Line1D(), branches=2, depth=1, policy=draw).estimate(np.zeros((1, 1)))
    assert str(e.value) == "estimate() needs rng (a numpy Generator) for a custom policy"
    bad = RiskEstimator(Line1D(), branches=2, depth=1, policy=lambda s, rng: np.zeros((s.shape[0], 2)))
    with pytest.raises(ValueError) as e:
        bad.estimate(np.zeros((3, 1)), np.random.default_rng(0))
    assert str(e.value) == "policy returned shape (6, 2), expected (6, 1)"
    with pytest.raises(TypeError) as e:
        RiskEstimator(Line1D(), policy="uniform")
    assert str(e.value) == "policy must be callable policy(states, rng) -> controls, got 'uniform'"


def test_default_chunk_keeps_a_chunk_at_about_32768_leaves():
    for n, m, chunk in ((32, 2, 32), (4, 3, 512), (5, 1, 6553), (2, 0, 32768), (200, 2, 1)):
        est = RiskEstimator(Line1D(), branches=n, depth=m)
        assert est.chunk_size == chunk
        assert est.chunk_size * n**m <= max(32768, n**m)  # the bound on one chunk's leaves (one root at least)
    assert RiskEstimator(Line1D(), chunk_size=3).chunk_size == 3


def test_tree_size_refusals_say_how_large():
    with pytest.raises(ValueError) as e:
        RiskEstimator(Line1D(), branches=1025, depth=2)
    assert str(e.value) == (
        "branches (n, --branches) = 1025 and depth (m, --depth) = 2 make a tree of 1,051,650 nodes per "
        "state (n + n^2 + ... + n^m); at most 1,048,576 are supported (the paper uses n = 32, m = 2: "
        "1,056): lower --branches or --depth"
    )
    with pytest.raises(ValueError) as e:
        RiskEstimator(Line1D(), branches=2**40, depth=2)
    assert "make a tree of more than 2^64 nodes per state" in str(e.value)
    RiskEstimator(Line1D(), branches=1, depth=2**20)  # exactly 2^20 nodes: the largest accepted
    with pytest.raises(ValueError, match="make a tree of 1,048,577 nodes"):
        RiskEstimator(Line1D(), branches=1, depth=2**20 + 1)


def test_tree_nodes_by_hand():
    from rmm_envs.risk.estimator import tree_nodes

    assert [tree_nodes(1, 5), tree_nodes(3, 2), tree_nodes(32, 2), tree_nodes(2, 0)] == [5, 12, 1056, 0]
    assert tree_nodes(2, 64) == 2**65 - 2 and tree_nodes(2, 65) == math.inf  # exact up to 2^64 levels' worth


def test_metric_names_and_refusals():
    assert get_metric("worst") is worst_case and get_metric("worst_case") is worst_case
    assert get_metric("cvar", 0.25)(np.array([0.0, 0.0, 0.0, 1.0])) == 1.0
    with pytest.raises(ValueError) as e:
        get_metric("median")
    assert str(e.value) == "unknown risk metric 'median'; expected one of ['expected', 'cvar', 'worst']"
    for alpha in (None, 1, 0.0, float("nan"), "0.5"):
        with pytest.raises(ValueError) as e:
            get_metric("cvar", alpha)
        assert str(e.value) == f"cvar needs alpha in the open interval (0, 1), got {alpha!r}"


class NoLeafLine1D:
    """Line1D without the optional leaf_estimate."""

    state_dim, control_dim = 1, 1
    control_low, control_high = np.array([0.0]), np.array([3.0])
    propagate, path_failed, state_failed = Line1D.propagate, Line1D.path_failed, Line1D.state_failed
    wall = 1.0


def test_defaults_and_params_are_pinned():
    from rmm_envs.risk.estimator import validate_tree_params

    assert RiskEstimator(Line1D()).params() == {
        "branches": 32,
        "depth": 2,
        "horizon": 2.0,
        "n_steps": 8,
        "metric": "expected",
        "alpha": None,
        "leaf": "zero",
        "policy": "uniform",
    }

    def my_policy(states, rng):
        return np.zeros((states.shape[0], 1))

    p = RiskEstimator(
        Line1D(),
        branches=3,
        depth=1,
        horizon=0.5,
        n_steps=4,
        metric="cvar",
        alpha=0.3,
        leaf="heuristic",
        policy=my_policy,
    ).params()
    assert p == {
        "branches": 3,
        "depth": 1,
        "horizon": 0.5,
        "n_steps": 4,
        "metric": "cvar",
        "alpha": 0.3,
        "leaf": "heuristic",
        "policy": "my_policy",
    }
    assert validate_tree_params(32, 2, 2.0, 8) is None  # the defaults of the check are valid ones


def test_leaf_estimate_is_needed_only_for_the_heuristic_leaf():
    r = RiskEstimator(NoLeafLine1D(), branches=2, depth=1, horizon=1.0, n_steps=2).estimate(
        np.zeros((1, 1)), controls=ctl([0.5, 2.0])
    )
    assert r.risk[0] == 0.5
    with pytest.raises(TypeError) as e:
        RiskEstimator(NoLeafLine1D(), leaf="heuristic")
    assert str(e.value) == "leaf='heuristic' needs NoLeafLine1D.leaf_estimate(states)"


def test_estimate_refusals_and_result_types_are_pinned():
    est = RiskEstimator(Line1D(), branches=3, depth=2, horizon=1.0, n_steps=2)
    cases = [
        (dict(states=np.array([[np.inf]]), rng=np.random.default_rng(0)), "states must be finite"),
        (dict(states=np.zeros((1, 1))), "estimate() needs rng (a numpy Generator) or explicit controls"),
        (dict(states=np.zeros((1, 1)), controls=ctl([0.1] * 3)), "controls must have one array per level (2), got 1"),
        (
            dict(states=np.zeros((1, 1)), controls=ctl([0.1] * 3, [0.1] * 6)),
            "controls[1] must have shape (1, 9, c), got (1, 6, 1)",
        ),
        (
            dict(states=np.zeros((1, 1)), controls=ctl([0.1] * 2, [0.1] * 9)),
            "controls[0] must have shape (1, 3, c), got (1, 2, 1)",
        ),
    ]
    for kw, text in cases:
        with pytest.raises(ValueError) as e:
            est.estimate(**kw)
        assert str(e.value) == text
    r = est.estimate(np.zeros((2, 1)), np.random.default_rng(0))
    assert r.n_leaves.dtype == np.int64 and r.risk.dtype == np.float64


def test_object_arrays_of_numbers_are_read_as_floats():
    """States and candidates are converted to float: an object array of numbers (as a pandas column
    of Python floats gives) labels exactly as the float array does, on the compiled Dubins4D scene."""
    sc = scene([[3.0, 0.0, 1.0]])
    est = RiskEstimator(sc, branches=4, depth=1)
    states = np.array([[0.0, 0.0, 0.0, 1.0], [1.0, 0.5, 0.2, 2.0]])
    obj = states.astype(object)
    np.testing.assert_array_equal(
        est.estimate(obj, np.random.default_rng(0)).risk, est.estimate(states, np.random.default_rng(0)).risk
    )
    cands = np.array([[0.0, -0.5], [0.25, 0.5]])
    ref = est.estimate_candidates(states, cands, hold=1.0, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(
        est.estimate_candidates(obj, cands.astype(object), hold=1.0, rng=np.random.default_rng(1)), ref
    )


def test_the_tree_after_a_candidate_starts_where_the_held_branch_ends():
    """The tree's policy sees the live ends, root-major and candidate-minor: x + u * hold."""
    seen = []

    def record(states, rng):
        seen.append(states[::2, 0].tolist())  # two branches per end
        return np.zeros((states.shape[0], 1))

    est = RiskEstimator(Line1D(), branches=2, depth=1, horizon=1.0, n_steps=5, policy=record)
    r = est.estimate_candidates(
        np.array([[0.0], [0.25]]), [[0.2], [0.5], [2.0]], hold=1.5, rng=np.random.default_rng(0)
    )
    assert seen == [[0.2 * 1.5, 0.5 * 1.5, 0.25 + 0.2 * 1.5]]  # 2.0 * 1.5 and 0.25 + 0.5 * 1.5 = 1 reach the wall
    np.testing.assert_array_equal(
        r, [[0.0, 0.0, 1.0], [0.0, 1.0, 1.0]]
    )  # u = 0 afterwards: only the held branches fail


class Float64OnlyLine1D(Line1D):
    """Line1D that refuses anything but float64 states (as a kernel compiled for float64 would)."""

    def _check(self, a):
        assert a.dtype == np.float64, a.dtype
        return a

    def propagate(self, states, controls, duration, n_steps):
        return super().propagate(self._check(states), controls, duration, n_steps)

    def state_failed(self, states):
        return super().state_failed(self._check(states))


def test_the_system_is_given_float64_states_whatever_the_caller_passes():
    est = RiskEstimator(Float64OnlyLine1D(), branches=2, depth=1, horizon=1.0, n_steps=2)
    for roots in (np.array([[0], [2]]), np.array([[0.0], [2.0]], np.float32), [[0], [2]]):
        assert est.estimate(roots, controls=[np.array([[[0.5], [0.9]]] * 2)]).risk.tolist() == [0.0, 1.0]
        held = RiskEstimator(Float64OnlyLine1D(), depth=0, n_steps=2)  # the held branch's failure only
        np.testing.assert_array_equal(
            held.estimate_candidates(roots, [[0.0], [1.0]], hold=1.0, rng=np.random.default_rng(0)),
            [[0.0, 1.0], [1.0, 1.0]],
        )
