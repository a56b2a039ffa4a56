"""The compiled per-decision paths of the guardians agree with their plain definitions.

Each guardian decision runs a compiled loop where numpy's per-call overhead dominated: the HJ
value lookup (:meth:`Grid.interpolator`), the LRMM forward pass for one observation, the CBF's
barrier rows and its OSQP calls.  These tests hold each one to an independent statement of
the same maths (exact where the arithmetic is the same, 1e-12 where only the order of a sum
differs).
"""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.dubins4d.driver import desired_heading
from rmm_guardians.cbf.barrier import BarrierRows, HOCBFParams, any_row_active, barrier_rows
from rmm_guardians.cbf.qp import BarrierQP
from rmm_guardians.hj.grid import Grid
from rmm_guardians.lrmm.model import ACTIVATIONS, LRMMModel

finite = st.floats(-50, 50, allow_nan=False)


# ---------------------------------------------------------------------- HJ grid lookup
def _grid4():
    return Grid([-2.0, -1.0, -np.pi, 0.0], [2.0, 3.0, np.pi, 2.0], [7, 6, 8, 5], periodic=[2])


def _multilinear(g, x):
    """A function multilinear interpolation reproduces exactly on non-periodic axes."""
    return 1.5 + 0.3 * x[0] - 2.0 * x[1] + 0.7 * x[3] + 0.25 * x[0] * x[1] - 0.5 * x[1] * x[3]


@functools.lru_cache(maxsize=1)
def _multilinear_case():
    g = _grid4()
    X = np.meshgrid(*g.axes, indexing="ij")
    A = _multilinear(g, X).astype(np.float32)
    B = (np.cos(X[2]) + X[0]).astype(np.float32)  # depends on the periodic axis
    return g, A, B, g.interpolator([A, B])


@settings(max_examples=60, deadline=None)
@given(st.floats(-2, 2), st.floats(-1, 3), st.floats(-10, 10), st.floats(0, 2))
def test_interpolator_reproduces_a_multilinear_function_exactly(x, y, th, v):
    g, A, B, f = _multilinear_case()
    p = np.array([x, y, th, v])
    out = f(p)
    assert out.shape == (2,)
    # float32 storage: the corner values carry ~1e-7 relative error
    assert out[0] == pytest.approx(_multilinear(g, p), abs=1e-5)
    np.testing.assert_allclose(out, g.interp_many([A, B], p), rtol=0, atol=1e-12)
    # the periodic axis wraps: theta and theta + 2 pi give the same values
    np.testing.assert_allclose(f(p + np.array([0, 0, 2 * np.pi, 0])), out, atol=1e-9)


def test_interpolator_clamps_outside_the_box_as_interp_many_and_checks_shapes():
    g = _grid4()
    rng = np.random.default_rng(3)
    A = rng.normal(size=g.shape).astype(np.float32)
    f = g.interpolator([A])
    for p in ([-5.0, 10.0, 0.3, -1.0], [2.0, 3.0, np.pi, 2.0], [-2.0, -1.0, -np.pi, 0.0], [9.0, -9.0, 7.0, 5.0]):
        assert f(np.array(p))[0] == pytest.approx(g.interp_many([A], np.array(p))[0], abs=1e-12)
    with pytest.raises(ValueError, match=r"grid's shape \(7, 6, 8, 5\)"):
        g.interpolator([np.zeros((7, 6, 8))])


# ---------------------------------------------------------------------- LRMM one observation
def _model(activation, features=None, obs_dim=6, hidden=(9, 5), n_out=1, seed=0):
    rng = np.random.default_rng(seed)
    feats = list(range(obs_dim)) if features is None else features
    sizes = [len(feats), *hidden, n_out]
    weights = [
        (rng.normal(size=(b, a)), rng.normal(size=b) if i < len(sizes) - 2 or seed % 2 else None)
        for i, (a, b) in enumerate(zip(sizes[:-1], sizes[1:], strict=True))  # consecutive layer sizes
    ]
    meta = {"features": feats, "obs_dim": obs_dim, "activation": activation}
    if n_out > 1:
        meta["candidates"] = rng.uniform(-1, 1, size=(n_out - 1, 2)).tolist()
    return LRMMModel(weights, rng.uniform(-1, 0, len(feats)), rng.uniform(0.5, 2, len(feats)), meta)


def _reference_forward(m, x):
    """The network written out from its stored weights and scaler (no folding, no compilation)."""
    h = (np.asarray(x, float)[m.features] - m.scaler_min) * m.scaler_scale
    act = {
        "sigmoid": lambda z: 1 / (1 + np.exp(-z)),
        "tanh": np.tanh,
        "relu": lambda z: np.maximum(z, 0),
        "elu": lambda z: np.where(z > 0, z, np.expm1(np.minimum(z, 0))),
    }[m.meta["activation"]]
    for i, (W, b) in enumerate(m.weights):
        z = W @ h + (0 if b is None else b)
        h = 1 / (1 + np.exp(-z)) if i == len(m.weights) - 1 else act(z)
    return h


@pytest.mark.parametrize("activation", ACTIVATIONS)
@pytest.mark.parametrize("features,n_out,seed", [(None, 1, 0), ([4, 1, 2], 4, 1)])
def test_one_observation_inference_matches_the_written_out_network(activation, features, n_out, seed):
    m = _model(activation, features=features, n_out=n_out, seed=seed)
    X = np.random.default_rng(7).uniform(-3, 3, size=(50, m.obs_dim))
    batch = m.predict_all(X)
    for x, row in zip(X, batch, strict=True):  # one output row per observation
        one = m.predict_all(x)
        assert one.shape == (n_out,)
        np.testing.assert_allclose(one, _reference_forward(m, x), rtol=0, atol=1e-12)
        np.testing.assert_allclose(one, row, rtol=0, atol=1e-12)
        assert m.predict(x) == one[0]


def test_the_batch_kernel_gives_each_row_the_bits_of_the_one_observation_kernel_and_nan_for_a_bad_row():
    from rmm_guardians.lrmm.inference import forward_one, forward_rows

    m = _model("tanh", n_out=3, seed=2)
    X = np.random.default_rng(3).uniform(-3, 3, size=(6, m.obs_dim))
    X[4, 2] = np.inf
    out = forward_rows(X, m._Ws, m._bs, m._act_code)
    assert out.shape == (6, 3)
    for i in (0, 1, 2, 3, 5):
        np.testing.assert_array_equal(out[i], forward_one(X[i], m._Ws, m._bs, m._act_code))
    assert np.isnan(out[4]).all() and forward_one(X[4], m._Ws, m._bs, m._act_code) is None


def test_one_observation_inference_refuses_non_finite_and_misshapen_input():
    m = _model("relu")
    for bad in (np.nan, np.inf, -np.inf):
        x = np.zeros(6)
        x[3] = bad
        with pytest.raises(ValueError, match="NaN or inf"):
            m.predict_all(x)
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        m.predict_all(np.zeros(5))


# ---------------------------------------------------------------------- CBF rows and QP
PRM = HOCBFParams(
    p1=1.0,
    p2=2.0,
    gamma_vmin=1.0,
    gamma_vmax=1.0,
    lambda_theta=1.0,
    lambda_v=1.0,
    u1_min=-0.25,
    u1_max=0.25,
    u2_min=-0.5,
    u2_max=0.5,
    v_min=0.0,
    v_max=2.0,
)


def _rows_by_hand(state, obstacles, radii, goal, p):
    """The rows as the package docstring derives them, one obstacle at a time."""
    x, y, th, v = state
    K = len(obstacles)
    G, h = np.zeros((K + 6, 4)), np.zeros(K + 6)
    for i, (ox, oy, _) in enumerate(obstacles):
        dx, dy = x - ox, y - oy
        b = dx * dx + dy * dy - radii[i] ** 2
        lfb = 2 * v * (dx * math.cos(th) + dy * math.sin(th))
        G[i, 0] = -2 * v * (dy * math.cos(th) - dx * math.sin(th))
        G[i, 1] = -2 * (dx * math.cos(th) + dy * math.sin(th))
        h[i] = 2 * v * v + p.p1 * lfb + p.p2 * (lfb + p.p1 * b)
    G[K, 0], h[K] = 1, p.u1_max
    G[K + 1, 0], h[K + 1] = -1, -p.u1_min
    G[K + 2, 1], h[K + 2] = 1, min(p.u2_max, p.gamma_vmax * (p.v_max - v))
    G[K + 3, 1], h[K + 3] = -1, -max(p.u2_min, -p.gamma_vmin * (v - p.v_min))
    xh, yh = goal[0] - x, goal[1] - y
    d2 = xh * xh + yh * yh
    thw = (th + math.pi) % (2 * math.pi) - math.pi
    e = thw - desired_heading(thw, math.atan2(yh, xh))
    lfv = 2 * v * e * (xh * math.sin(thw) - yh * math.cos(thw)) / d2 if d2 > 0 else 0.0
    G[K + 4, 0], G[K + 4, 2], h[K + 4] = 2 * e, -1, -lfv - p.lambda_theta * e * e
    d = math.sqrt(d2)
    ev = v - min((d / 2) ** 2, d / 2)
    G[K + 5, 1], G[K + 5, 3], h[K + 5] = 2 * ev, -1, -p.lambda_v * ev * ev
    return G, h


@settings(max_examples=80, deadline=None)
@given(finite, finite, st.floats(-7, 7), st.floats(0, 2), st.integers(0, 6), st.integers(0, 2**31))
def test_barrier_rows_equal_the_hand_derivation(x, y, th, v, K, seed):
    rng = np.random.default_rng(seed)
    obstacles = np.column_stack([rng.uniform(-20, 20, (K, 2)), rng.uniform(0.5, 3, K)])
    radii = obstacles[:, 2] * rng.uniform(1, 1.5, K)
    goal = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), 1.0])
    state = np.array([x, y, th, v])
    G, h = barrier_rows(state, obstacles, radii, goal, PRM)
    G2, h2 = _rows_by_hand(state, obstacles, radii, goal, PRM)
    np.testing.assert_allclose(G, G2, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(h, h2, rtol=1e-12, atol=1e-9)
    G3, h3 = BarrierRows(obstacles, radii, goal, PRM)(state)
    assert np.array_equal(G, G3) and np.array_equal(h, h3)


def test_any_row_active_by_hand():
    # rows 0, 1 are barriers (K = 2); row 2 is not a barrier and is ignored
    G = np.array([[1.0, 0, 0, 0], [0, 2.0, 0, 0], [1.0, 1.0, 0, 0]])
    h = np.array([1.0, 5.0, 0.0])
    z = np.array([0.9995, 1.0, 0, 0])  # gaps: 0.0005, 3.0, (-2.0)
    assert any_row_active(G, h, z, 2, 1e-3, 0.0)
    assert not any_row_active(G, h, z, 2, 1e-4, 0.0)
    assert any_row_active(G, h, z, 2, 1e-4, 1e-3)  # 1e-4 + 1e-3 * |h_0| = 1.1e-3 >= 5e-4
    assert not any_row_active(G, h, np.array([0.0, 0.0, 0, 0]), 2, 1e-3, 0.0)
    assert not any_row_active(G, h, z, 0, 1.0, 1.0)  # no barriers, nothing active


def test_direct_osqp_calls_give_what_the_wrapper_gives():
    rng = np.random.default_rng(11)
    K = 4
    obstacles = np.column_stack([rng.uniform(-10, 10, (K, 2)), rng.uniform(1, 2, K)])
    radii = 1.2 * obstacles[:, 2]
    goal = np.array([15.0, 15.0, 1.0])
    fast, wrapped = BarrierQP(K, PRM, 1.0, 1.0, 1e-6), BarrierQP(K, PRM, 1.0, 1.0, 1e-6)
    assert fast._native is not None, "osqp >= 1.0 exposes its compiled solver; the direct path must be used"
    wrapped._native = None
    rows = BarrierRows(obstacles, radii, goal, PRM)
    solved = 0
    for _ in range(60):
        G, h = rows(np.array([*rng.uniform(-12, 12, 2), rng.uniform(-3, 3), rng.uniform(0, 2)]))
        a, b = fast.solve(G, h), wrapped.solve(G, h)
        assert (a is None) == (b is None)
        if a is not None:
            solved += 1
            assert np.array_equal(a, b)
            assert np.all(G @ a <= h + 1e-4)
    assert solved > 30


# ---------------------------------------------------------------------- one-state prediction
@settings(max_examples=150, deadline=None)
@given(
    finite,
    finite,
    st.floats(-7, 7),
    st.floats(-1, 3),
    st.floats(-1, 1),
    st.floats(-1, 1),
    st.one_of(st.just(0.0), st.floats(0, 6)),
)
def test_state_after_is_states_at_for_one_state_bit_for_bit(x, y, th, v, w, a, t):
    from rmm_envs.systems.dubins4d.dynamics import Dubins4D

    d = Dubins4D()
    s, u = np.array([x, y, th, v]), np.array([w, a])
    out = d.state_after(s, u, t)
    assert out.shape == (4,)
    assert np.array_equal(out, d.states_at(s[None], u[None], np.array([t]), compiled=True)[0, 0])
    np.testing.assert_allclose(out, d.states_at(s[None], u[None], np.array([t]), compiled=False)[0, 0], atol=1e-9)
