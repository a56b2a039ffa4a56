"""The per-world kernels the single and the vector env share: batch-independent, bit for bit,
and equal to the plain formulas they replace."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.dubins4d.circles import (
    CircleWorld,
    contact_params,
    contact_params_each,
    points_in_circles,
    ray_cast,
    ray_cast_each,
    ray_cast_numpy,
)
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, _states_at_compiled


def _worlds(rng, n, k=5):
    return np.stack([CircleWorld.generate(rng, k) for _ in range(n)])


def test_rays_each_equal_one_origin_at_a_time_and_the_numpy_formulas():
    rng = np.random.default_rng(0)
    circles = _worlds(rng, 300)
    xy = rng.uniform(-14, 14, (300, 2))
    th = rng.uniform(-7, 7, 300)
    each = ray_cast_each(xy, th, circles)
    one = np.array([ray_cast(xy[i : i + 1], th[i : i + 1], circles[i])[0] for i in range(300)])
    assert np.array_equal(each, one)  # the same compiled function, whatever the batch
    ref = np.array([ray_cast_numpy(xy[i : i + 1], th[i : i + 1], circles[i], 12, 10.0)[0] for i in range(300)])
    np.testing.assert_allclose(each, ref, rtol=0, atol=1e-12)
    assert np.any(each == 0.0) and np.any(each == 10.0) and np.any((each > 0) & (each < 10))


def _contact_reference(path, circles):
    """The contact parameter written out directly: every segment of every circle, no skipping."""
    out = []
    for cx, cy, r in circles:
        best = math.inf
        for j in range(len(path) - 1):
            (px, py), (qx, qy) = path[j, :2], path[j + 1, :2]
            dx, dy, fx, fy = qx - px, qy - py, px - cx, py - cy
            a, b, c = dx * dx + dy * dy, fx * dx + fy * dy, fx * fx + fy * fy - r * r
            if c <= 0:
                best = float(j)
                break
            disc = b * b - a * c
            if a > 0 and disc >= 0 and 0 <= (s := (-b - math.sqrt(disc)) / a) <= 1:
                best = j + s
                break
        out.append(best)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31), duration=st.floats(0.05, 6.0))
def test_contacts_each_equal_the_direct_formula(seed, duration):
    """The reach pre-test only skips circles a path cannot touch: results are those of the
    direct formula, bit for bit, and do not depend on the batch."""
    rng = np.random.default_rng(seed)
    n = 40
    circles = np.concatenate([_worlds(rng, n), rng.uniform([-10, -10, 0.1], [10, 10, 1.0], (n, 1, 3))], axis=1)
    states = np.column_stack([rng.uniform(-10, 10, (n, 2)), rng.uniform(-np.pi, np.pi, n), rng.uniform(0, 2, n)])
    controls = rng.uniform([-0.25, -0.5], [0.25, 0.5], (n, 2))
    paths = Dubins4D().propagate(states, controls, duration, 16)
    each = contact_params_each(paths, circles)
    for i in range(n):
        assert np.array_equal(each[i], _contact_reference(paths[i], circles[i]))
        assert np.array_equal(each[i], contact_params(paths[i], circles[i]))


def test_states_at_compiled_does_not_depend_on_the_batch():
    rng = np.random.default_rng(2)
    s = np.column_stack([rng.uniform(-10, 10, (64, 2)), rng.uniform(-7, 7, 64), rng.uniform(-0.5, 2.5, 64)])
    u = rng.uniform(-1, 1, (64, 2))
    sys_ = Dubins4D()
    t = np.linspace(0, 3.0, 16)
    batch = sys_.states_at(s, u, t, compiled=True)
    one = np.array([sys_.states_at(s[i : i + 1], u[i : i + 1], t)[0] for i in range(64)])  # N = 1: compiled too
    assert np.array_equal(batch, one)
    assert _states_at_compiled is not None
    np.testing.assert_allclose(batch, sys_._states_at_numpy(s, u, t), rtol=0, atol=1e-12)


def test_one_point_in_circles_equals_the_batch():
    rng = np.random.default_rng(3)
    circles = CircleWorld.generate(rng)
    pts = rng.uniform(-12, 12, (4000, 2))
    pts[:5] = circles[:5, :2] + rng.uniform(-0.6, 0.6, (5, 2)) * circles[:5, 2:]  # certainly inside
    batch = points_in_circles(pts, circles)
    assert batch[:5].all() and not batch.all()
    assert np.array_equal(batch, [points_in_circles(p[None], circles)[0] for p in pts])
    # the boundary counts (exact dyadic numbers), one point or many
    c = np.array([[1.0, 2.0, 0.5], [-4.0, 0.0, 0.25]])
    on = np.array([[1.5, 2.0], [-4.0, -0.25], [1.5, 2.0000001]])
    assert points_in_circles(on, c).tolist() == [True, True, False]
    assert [points_in_circles(p[None], c)[0] for p in on] == [True, True, False]
