"""The maze ``hj``'s look-ahead geometry (``guardians/hj/maze_lookahead.py``) against exact arcs.

The reference here is written independently of the module: the car's path under a held turn
rate ``u`` is a circle arc of radius ``s / |u|`` (a line when ``u = 0``), and a wall is a capsule
(a segment thickened by ``half``), so the clearance of a point is its distance to the segment
less ``half``.  A manoeuvre's score must never state more clearance than the exact path keeps
(a certified manoeuvre never comes within the margin of a wall), and states at most one half
sample's travel less.  These tests run quickly with the compiler off (``make mutate``'s
``maze_lookahead`` target runs them so)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from rmm_guardians.hj.maze_lookahead import COEF, manoeuvres, near_walls, path_clearances

SPEED, DT, HALF = 10.0, 0.2, 6.25
# a closed box 500 x 250 px with one inner wall hanging from the top (capsules of half-width 6.25)
BOX = np.array(
    [
        [62.5, 62.5, 437.5, 62.5],
        [62.5, 187.5, 437.5, 187.5],
        [62.5, 62.5, 62.5, 187.5],
        [437.5, 62.5, 437.5, 187.5],
        [250.0, 187.5, 250.0, 140.0],
    ]
)


def exact_pose(x, y, psi, u, t):
    """The pose after holding turn rate ``u`` for ``t`` s at ``SPEED`` (closed-form arc)."""
    if u == 0.0:
        return x + SPEED * t * math.cos(psi), y + SPEED * t * math.sin(psi), psi
    r = SPEED / u
    return x + r * (math.sin(psi + u * t) - math.sin(psi)), y - r * (math.cos(psi + u * t) - math.cos(psi)), psi + u * t


def exact_path(x, y, psi, row, step):
    """Points of manoeuvre ``row = (u1, t1, u2, t2)`` every ``step`` s, both ends included."""
    u1, t1, u2, t2 = row
    ts = np.append(np.arange(0.0, t1 + t2, step), t1 + t2)
    x1, y1, p1 = exact_pose(x, y, psi, u1, t1)
    return np.array(
        [exact_pose(x, y, psi, u1, t)[:2] if t <= t1 else exact_pose(x1, y1, p1, u2, t - t1)[:2] for t in ts]
    )


def clearance(points, walls, half):
    """Distance of each point to the nearest capsule's surface (vectorised, exact)."""
    a, b = walls[None, :, :2], walls[None, :, 2:]
    p = points[:, None, :]
    d = b - a
    dd = (d * d).sum(-1)
    t = np.clip(np.where(dd > 0, ((p - a) * d).sum(-1) / np.where(dd > 0, dd, 1.0), 0.0), 0.0, 1.0)
    e = a + t[..., None] * d - p
    return np.sqrt((e * e).sum(-1)).min(1) - half


def score(x, y, psi, man, walls=BOX, half=HALF, width=500.0, height=250.0, dt=DT):
    clear, ends = np.empty(len(man)), np.empty((len(man), 3))
    out = path_clearances(x, y, psi, SPEED, np.asarray(man, float), dt, walls, half, width, height, COEF, clear, ends)
    assert out is clear
    return clear, ends


# ------------------------------------------------------------------ the manoeuvre table
def test_manoeuvre_table_hand_listed():
    loop = 2 * math.pi / 0.5
    rows = [[-0.5, 0.0, -0.5, loop], [0.0, 0.0, 0.0, 3.0], [0.5, 0.0, 0.5, loop]]
    for t1 in (1.0, 2.0):
        rows += [
            [-0.5, t1, 0.0, 3.0 - t1],
            [-0.5, t1, 0.5, loop],
            [0.0, t1, -0.5, loop],
            [0.0, t1, 0.5, loop],
            [0.5, t1, -0.5, loop],
            [0.5, t1, 0.0, 3.0 - t1],
        ]
    got = manoeuvres(0.5, 3.0, steps=3)
    assert got.shape == (15, 4) and np.allclose(got, rows, rtol=0.0, atol=1e-12)
    six = manoeuvres(0.2, 6.0)  # the default: 3 + 5 x 6 rows, switches at whole seconds
    assert six.shape == (33, 4) and six.dtype == float
    assert sorted(set(six[:, 1].tolist())) == pytest.approx([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])


# ------------------------------------------------------------------ the walls in reach
def test_near_walls_hand_computed_boundary():
    walls = np.array(
        [
            [-10.0, 0.0, 10.0, 0.0],  # 7 px below (0, 7): exactly reach + half
            [20.0, 7.0, 30.0, 7.0],  # its nearest end 20 px away
            [0.0, 14.5, 0.0, 14.5],  # a point (zero length) 7.5 px above
            [-3.0, 9.0, -3.0, 30.0],
        ]
    )  # its lower end (-3, 9): sqrt(13) px
    got = near_walls(walls, 0.0, 7.0, 5.0, 2.0)
    assert got.tolist() == [walls[0].tolist(), walls[3].tolist()] and got.flags.c_contiguous
    assert near_walls(walls, 0.0, 7.0, 5.5, 2.0).tolist() == [walls[0].tolist(), walls[2].tolist(), walls[3].tolist()]
    assert near_walls(walls, 0.0, 7.0, 1.7, 2.0).tolist() == [walls[3].tolist()]
    assert near_walls(walls, 0.0, 7.0, 1.6, 2.0).shape == (0, 4)
    assert near_walls(walls, 25.0, 7.0, 0.0, 0.0).tolist() == [walls[1].tolist()]  # on the segment itself
    # a wall 1 px long (its squared length exactly 1): projected like any other; (1, 5) is 5 px
    # from its end (1, 0), sqrt(26) from its start
    short = np.array([[0.0, 0.0, 1.0, 0.0]])
    assert near_walls(short, 1.0, 5.0, 5.02, 0.0).shape == (1, 4) and near_walls(short, 1.0, 5.0, 4.98, 0.0).shape == (
        0,
        4,
    )
    # integer walls come back as floats; a zero-length wall (0 / 0 projected) warns of nothing
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = near_walls(np.array([[0, 0, 0, 0], [3, 4, 3, 4], [0, 9, 9, 9]]), 0.0, 0.0, 5.0, 0.0)
    assert got.dtype == np.float64 and got.tolist() == [[0.0, 0.0, 0.0, 0.0], [3.0, 4.0, 3.0, 4.0]]


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 500.0), st.floats(0.0, 250.0), st.floats(0.0, 300.0), st.floats(0.0, 10.0))
def test_near_walls_are_exactly_those_within_reach(x, y, reach, half):
    walls = np.vstack([BOX, [[300.0, 100.0, 300.0, 100.0]]])  # with a zero-length wall
    dist = np.array([_seg_dist(x, y, *w) for w in walls])
    got = {tuple(w) for w in near_walls(walls, x, y, reach, half)}
    for w, d in zip(walls, dist, strict=True):  # one distance per wall
        if abs(d - (reach + half)) > 1e-6:  # on the boundary either answer is rounding
            assert (tuple(w) in got) == (d <= reach + half)


def _seg_dist(px, py, ax, ay, bx, by):
    """Point-segment distance by projection (plain floats)."""
    vx, vy = bx - ax, by - ay
    L2 = vx * vx + vy * vy
    t = 0.0 if L2 == 0 else max(0.0, min(1.0, ((px - ax) * vx + (py - ay) * vy) / L2))
    return math.hypot(ax + t * vx - px, ay + t * vy - py)


# ------------------------------------------------------------------ path clearances by hand
def test_straight_at_a_wall_hand_computed():
    # from (150, 125) along +x for 6 s: the end (210, 125) is nearest the inner wall's lower
    # end (250, 140): sqrt(40^2 + 15^2) - 6.25, less half a sample's travel (1 px)
    clear, ends = score(150.0, 125.0, 0.0, [[0.0, 0.0, 0.0, 6.0]])
    assert clear[0] == pytest.approx(math.hypot(40.0, 15.0) - 6.25 - 1.0, abs=1e-9)
    assert ends[0].tolist() == pytest.approx([210.0, 125.0, 0.0], abs=1e-9)
    # the same from (200, 125): the path passes under the inner wall's end, 15 px from its centre line
    clear, ends = score(200.0, 125.0, 0.0, [[0.0, 0.0, 0.0, 6.0]])
    assert clear[0] == pytest.approx(15.0 - 6.25 - 1.0, abs=1e-9) and ends[0][0] == pytest.approx(260.0)
    # a coarser sampling states less, by half its own travel: 0.5 s (5 px) per sample
    assert score(200.0, 125.0, 0.0, [[0.0, 0.0, 0.0, 6.0]], dt=0.5)[0][0] == pytest.approx(15.0 - 6.25 - 2.5, abs=1e-9)


def test_two_turn_end_pose_hand_computed():
    # left at 0.2 rad/s (R = 50) for 5 s: a 1-rad arc, then straight for 1.3 s (not a whole number of samples)
    clear, ends = score(150.0, 100.0, 0.0, [[0.2, 5.0, 0.0, 1.3]], walls=BOX[:1], width=1e4, height=1e4)
    x1, y1 = 150.0 + 50.0 * math.sin(1.0), 100.0 + 50.0 * (1.0 - math.cos(1.0))
    assert ends[0].tolist() == pytest.approx([x1 + 13.0 * math.cos(1.0), y1 + 13.0 * math.sin(1.0), 1.0], abs=1e-9)
    # nearest the lower wall (centre line y = 62.5) at the start: 37.5 - 6.25, less 1 px
    assert clear[0] == pytest.approx(37.5 - 6.25 - 1.0, abs=1e-9)
    # right turn then left: the second arc starts where the first ends, at heading -1
    _, ends = score(150.0, 100.0, 0.0, [[-0.2, 5.0, 0.2, 5.0]], walls=BOX[:1], width=1e4, height=1e4)
    x1, y1, p1 = exact_pose(150.0, 100.0, 0.0, -0.2, 5.0)
    assert ends[0].tolist() == pytest.approx(list(exact_pose(x1, y1, p1, 0.2, 5.0)), abs=1e-9)


def test_leaving_the_image_is_minus_one_and_stops_there():
    # from (5, 100) heading -x: samples at x = 5, 3, 1, then -1 (outside [0, width]): stop there
    floor = np.array([[0.0, 0.0, 500.0, 0.0]])
    clear, ends = score(5.0, 100.0, math.pi, [[0.0, 0.0, 0.0, 6.0], [0.0, 0.0, 0.0, 0.4]], walls=floor)
    assert clear.tolist() == [-1.0, pytest.approx(100.0 - 6.25 - 1.0)]
    assert ends[0].tolist() == pytest.approx([-1.0, 100.0, math.pi], abs=1e-9)
    assert ends[1].tolist() == pytest.approx([1.0, 100.0, math.pi], abs=1e-9)
    # each edge of the image: above height, below 0, right of width
    for pose in ((100.0, 249.0, math.pi / 2), (100.0, 1.0, -math.pi / 2), (499.0, 100.0, 0.0)):
        assert score(*pose, [[0.0, 0.0, 0.0, 1.0]], walls=BOX[:1])[0][0] == -1.0
    # the image's far edges belong to it: samples exactly at x = width and at y = height
    assert score(490.0, 100.0, 0.0, [[0.0, 0.0, 0.0, 1.0]], walls=BOX[:1])[1][0].tolist() == [500.0, 100.0, 0.0]
    assert score(490.0, 100.0, 0.0, [[0.0, 0.0, 0.0, 1.0]], walls=BOX[:1])[0][0] == pytest.approx(
        math.hypot(52.5, 37.5) - 7.25
    )  # nearest at the start
    assert score(100.0, 240.0, math.pi / 2, [[0.0, 0.0, 0.0, 1.0]], walls=BOX[:1])[0][0] == pytest.approx(170.25)
    # leaving during the first turn (left at 0.2 rad/s from heading pi): the end is that sample's pose, heading included
    clear, ends = score(5.0, 100.0, math.pi, [[0.2, 5.0, 0.0, 1.0]], walls=BOX[:1])
    assert clear[0] == -1.0 and ends[0].tolist() == pytest.approx(
        list(exact_pose(5.0, 100.0, math.pi, 0.2, 0.6)), abs=1e-9
    )
    # a corner of the image is inside it; a manoeuvre of no duration is its one sample
    assert score(0.0, 0.0, 0.0, [[0.0, 0.0, 0.0, 0.0]], walls=BOX[:1])[0][0] == pytest.approx(
        math.hypot(62.5, 62.5) - 7.25
    )


@settings(max_examples=40, deadline=None)
@given(st.floats(75.0, 425.0), st.floats(75.0, 175.0), st.floats(-math.pi, math.pi), st.integers(0, 32))
@example(230.0, 120.0, 0.3, 25)  # turns round the inner wall's end
def test_a_certified_manoeuvre_keeps_its_clearance_on_the_exact_path(x, y, psi, m):
    row = manoeuvres(0.2, 6.0)[m]
    clear, ends = score(x, y, psi, [row])
    fine = exact_path(x, y, psi, row, DT / 40)
    inside = (fine[:, 0] >= 0) & (fine[:, 0] <= 500) & (fine[:, 1] >= 0) & (fine[:, 1] <= 250)
    if clear[0] == -1.0:
        assert not inside.all()
        return
    exact = float(clearance(fine, BOX, HALF).min())
    assert clear[0] <= exact + 1e-9  # never states more than the exact path keeps
    assert clear[0] >= exact - SPEED * DT / 2 - SPEED * DT / 80 - 1e-9  # and at most half a sample's travel less
    assert ends[0].tolist() == pytest.approx(
        list(exact_pose(*exact_pose(x, y, psi, row[0], row[1]), row[2], row[3])), abs=1e-6
    )
