import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from rmm_envs.systems.dubins4d.circles import (
    CircleWorld,
    as_circles,
    contact_params,
    first_contact,
    paths_hit_circles,
    points_in_circles,
    ray_cast,
    segments_hit_circles,
)

C = np.array([[5.0, 0.0, 1.0], [0.0, 5.0, 2.0]])


def test_points_boundary_counts():
    pts = np.array([[4.0, 0.0], [3.999, 0.0], [5.0, 0.0], [0.0, 3.0], [0.0, 2.999]])
    assert points_in_circles(pts, C).tolist() == [True, False, True, True, False]


def test_segments_hand_cases():
    p0 = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 1.0001], [10.0, 0.0]])
    p1 = np.array([[10.0, 0.0], [3.9, 0.0], [10.0, 1.0], [10.0, 1.0001], [6.0, 0.0]])
    # through; stops short; tangent (touches); just misses; ends inside from the far side
    assert segments_hit_circles(p0, p1, C[:1]).tolist() == [True, False, True, False, True]


def test_degenerate_segment_is_a_point():
    assert segments_hit_circles(np.array([[5.0, 0.5]]), np.array([[5.0, 0.5]]), C).tolist() == [True]


def test_rays_hand_computed():
    # heading 0 at the origin: ray 0 hits the circle at (5, 0) r 1 at 4 m; ray 3 (+90 deg) hits
    # the r=2 circle at (0, 5) at 3 m; ray 6 (backwards) sees nothing: 10
    r = ray_cast(np.zeros((1, 2)), np.zeros(1), C, 12, 10.0)[0]
    assert r[0] == pytest.approx(4.0)
    assert r[3] == pytest.approx(3.0)
    assert r[6] == 10.0
    # ray 1 (+30 deg) towards (5,0) r=1: miss (angle to tangent is asin(1/5) = 11.5 deg)
    assert r[1] == 10.0
    # an oblique hit: from (0, 0.5) heading 0, circle (5,0,1): 5 - sqrt(1 - 0.25)
    r = ray_cast(np.array([[0.0, 0.5]]), np.zeros(1), C[:1], 12, 10.0)[0]
    assert r[0] == pytest.approx(5 - math.sqrt(0.75))


def test_rays_from_inside_read_zero_and_cap():
    r = ray_cast(np.array([[5.0, 0.2]]), np.array([1.0]), C, 12, 10.0)[0]
    assert np.all(r == 0.0)
    far = ray_cast(np.array([[100.0, 100.0]]), np.zeros(1), C, 12, 10.0)[0]
    assert np.all(far == 10.0)
    assert ray_cast(np.zeros((2, 2)), np.zeros(2), np.zeros((0, 3)), 4, 3.0).tolist() == [[3.0] * 4] * 2


circles_st = st.lists(st.tuples(st.floats(-8, 8), st.floats(-8, 8), st.floats(0.2, 3)), min_size=1, max_size=6)


@settings(max_examples=80, deadline=None)
@given(circles=circles_st, x=st.floats(-10, 10), y=st.floats(-10, 10), th=st.floats(-4, 4))
def test_ray_never_reports_farther_than_the_nearest_obstacle(circles, x, y, th):
    c = np.array(circles)
    rays = ray_cast(np.array([[x, y]]), np.array([th]), c, 12, 10.0)[0]
    ang = th + 2 * np.pi * np.arange(12) / 12
    for d, a in zip(rays, ang, strict=True):  # 12 rays, 12 angles
        # sample the ray densely up to the reported distance: no point strictly before it is inside
        s = np.linspace(0, d, 200)[:-1]
        pts = np.c_[x + s * np.cos(a), y + s * np.sin(a)]
        if not points_in_circles(np.array([[x, y]]), c)[0]:
            inside = ((pts[:, None, :] - c[None, :, :2]) ** 2).sum(-1) < c[None, :, 2] ** 2 - 1e-9
            assert not inside.any()
        if d < 10.0 and d > 0:
            end = np.array([x + d * np.cos(a), y + d * np.sin(a)])
            dist = np.sqrt(((end - c[:, :2]) ** 2).sum(-1)) - c[:, 2]
            assert np.min(np.abs(dist)) < 1e-6  # the hit point lies on a circle


@settings(max_examples=60, deadline=None)
@given(circles=circles_st, seed=st.integers(0, 10_000))
def test_pruned_path_test_equals_brute_force(circles, seed):
    rng = np.random.default_rng(seed)
    c = np.array(circles)
    start = rng.uniform(-10, 10, (40, 1, 2))
    steps = rng.uniform(-1, 1, (40, 7, 2)).cumsum(axis=1)
    paths = np.concatenate([start, start + steps], axis=1)
    brute = segments_hit_circles(paths[:, :-1], paths[:, 1:], c).any(axis=1)
    assert paths_hit_circles(paths, c).tolist() == brute.tolist()


def test_contact_parameter_orders_contacts_within_a_segment():
    path = np.array([[0.0, 0.0], [10.0, 0.0]])
    cp = contact_params(path, np.array([[5.0, 0.0, 1.0], [3.0, 0.0, 0.5], [0.0, 9.0, 1.0]]))
    assert cp[0] == pytest.approx(0.4)
    assert cp[1] == pytest.approx(0.25)
    assert cp[2] == math.inf
    assert first_contact(path, C) == pytest.approx(0.4)
    # starting inside gives 0; a later segment gives j + s
    assert contact_params(np.array([[5.0, 0.0], [6.0, 0.0]]), C[:1])[0] == 0.0
    two = np.array([[0.0, 0.0], [2.0, 0.0], [4.5, 0.0]])
    assert first_contact(two, C) == pytest.approx(1 + 2.0 / 2.5)


def test_circle_validation():
    with pytest.raises(ValueError, match="radii"):
        as_circles([[0, 0, -1]])
    with pytest.raises(ValueError, match="triples"):
        as_circles([[0, 0]])
    with pytest.raises(ValueError, match="finite"):
        as_circles([[0, np.nan, 1]])
    with pytest.raises(ValueError, match="goal"):
        CircleWorld(C, goal=[0, 0, 0])


def test_generation_is_seeded_and_in_range():
    a = CircleWorld.generate(np.random.default_rng(3))
    b = CircleWorld.generate(np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert a.shape == (5, 3)
    assert np.all((a[:, 2] >= 2) & (a[:, 2] <= 5))
    assert np.all(np.abs(a[1:, :2]) <= 10)


@settings(max_examples=60, deadline=None)
@given(
    circles=st.lists(st.tuples(st.floats(-8, 8), st.floats(-8, 8), st.floats(0.2, 4)), min_size=1, max_size=6),
    x=st.floats(-10, 10),
    y=st.floats(-10, 10),
    th=st.floats(-7, 7),
)
def test_compiled_rays_equal_the_numpy_rays(circles, x, y, th):
    # a single origin (an env step) uses the compiled loop, a batch numpy: same numbers
    circ = np.array(circles)
    single = ray_cast(np.array([[x, y]]), np.array([th]), circ)
    batch = ray_cast(np.array([[x, y]] * 9), np.array([th] * 9), circ)  # 9 > the compiled cut-off
    np.testing.assert_allclose(single[0], batch[0], rtol=0, atol=1e-12)
