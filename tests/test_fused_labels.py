"""The fused risk-labelling loops give their numpy twins' bits (issue 54, item 4).

Each compiled path test of :mod:`rmm_envs.worlds.path_kernels` and
:mod:`rmm_envs.systems.quadrotor.room_kernels` equals the batched numpy test it replaces, each scene's
``propagate_failed`` (:mod:`rmm_envs.scenes.branch_kernels`) equals ``path_failed`` of
``propagate`` with the paths' last states, signed zeros included, and the estimator's labels are
the same bits with ``fused=True`` (the default) and ``fused=False`` (the separate calls).  Inputs
include the edge cases of the closed forms: zero coordinates and headings, speeds at and beyond
their bounds, controls at theirs, zero-width control boxes, horizons past the power series and
paths of more than 128 points (numpy's pairwise sum halves there).
"""

from __future__ import annotations

import numpy as np
import pytest

from rmm_envs.risk import RiskEstimator
from rmm_envs.risk.estimator import uniform_box
from rmm_envs.scenes import SceneBase
from rmm_envs.scenes import branch_kernels as bk
from rmm_envs.systems.dubins4d import dynamics as d4
from rmm_envs.systems.dubins4d.circles import paths_hit_circles
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.dubins4d.scene import Dubins4DScene
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.mazes import generate_maze
from rmm_envs.systems.maze.scene import MazeScene
from rmm_envs.systems.quadrotor.control import CommandController
from rmm_envs.systems.quadrotor.room_collision import RoomCollision, _box_sd
from rmm_envs.systems.quadrotor.room_kernels import room_shape_distance, room_states_failed
from rmm_envs.systems.quadrotor.rooms import generate_room
from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_envs.systems.quadrotor.scene import QuadrotorCommandScene, QuadrotorScene
from rmm_envs.worlds.path_kernels import circle_path_hit, maze_path_hit_near, pairwise_sum


def _bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


def _circles(rng, k):
    return np.column_stack([rng.uniform(-8, 8, k), rng.uniform(-8, 8, k), rng.uniform(0.2, 2.0, k)])


def _dubins4d_inputs(rng, n):
    s = np.column_stack(
        [rng.uniform(-10, 10, n), rng.uniform(-10, 10, n), rng.uniform(-7, 7, n), rng.uniform(-0.5, 2.5, n)]
    )
    s[::7, 0], s[::11, 1], s[::19, 2] = 0.0, -0.0, 0.0
    s[::5, 3], s[::13, 3], s[::17, 3] = 0.0, 2.0, -0.0
    u = rng.uniform([-0.4, -0.7], [0.4, 0.7], (n, 2))
    u[::3, 1], u[::9, 1], u[::4, 0], u[::23, 0], u[::29, 1] = -0.5, 0.5, 0.0, -0.0, -0.0
    return s, u


# ---------------------------------------------------------------------------- the path tests
def test_pairwise_sum_is_numpys_sum_of_a_row():
    rng = np.random.default_rng(0)
    for n in [*range(1, 140), 255, 256, 257, 300, 1000, 1029]:
        a = np.sqrt(rng.uniform(0, 10, (20, n)) * rng.uniform(0, 1, (20, 1)) ** 4)
        assert np.array_equal(np.array([pairwise_sum(row, n) for row in a]), a.sum(axis=1)), n


@pytest.mark.parametrize("n_points", [1, 2, 3, 8, 9, 16, 140])
def test_circle_path_hit_is_paths_hit_circles(n_points):
    rng = np.random.default_rng(n_points)
    for k in (0, 1, 5, 12):
        circles = _circles(rng, k)
        paths = np.cumsum(rng.normal(0, 0.6, (3000, n_points, 2)), axis=1) + rng.uniform(-9, 9, (3000, 1, 2))
        paths[::9, :, 0] = 0.0
        want = paths_hit_circles(paths, circles)
        scratch = np.empty(max(n_points - 1, 1))
        got = [circle_path_hit(p[:, 0].copy(), p[:, 1].copy(), n_points, circles, scratch) for p in paths]
        assert np.array_equal(got, want) and (k == 0 or 0 < want.mean() < 1)


def test_maze_path_hit_near_is_maze_paths_hit():
    rng = np.random.default_rng(1)
    maze = generate_maze(rng, rows=8, cols=8)
    for n_points in (2, 5, 8, 30):
        start = rng.uniform(-20, maze.width + 20, (3000, 1, 2))
        paths = (
            start
            + np.cumsum(rng.normal(0, 4.0, (3000, n_points, 2)), axis=1) * np.r_[0, np.ones(n_points - 1)][:, None]
        )
        want = maze.paths_hit(paths)
        cand = maze._candidates(paths[:, 0])
        d2 = np.empty(n_points * cand.shape[1])
        got = [
            maze_path_hit_near(
                p[:, 0].copy(), p[:, 1].copy(), n_points, maze._walls_ext, c, maze.half, maze.width, maze.height, d2
            )
            for p, c in zip(paths, cand, strict=True)
        ]
        assert np.array_equal(got, want) and 0.05 < want.mean() < 0.95


def _numpy_room_distances(col: RoomCollision, state: np.ndarray, kind: int, j: int) -> np.ndarray:
    """The ``sd`` row of RoomCollision.states_failed for one state and one shape, its numpy lines."""
    R = quat_to_rot(state[None, 3:7])
    world = state[None, None, :3] + np.einsum("kab,pb->kpa", R, col.points)
    if kind == -1:
        return _box_sd(world - col.walls[j, :3], col.walls[j, 3:])[0]
    local = np.einsum("kba,kpb->kpa", col.obj_R[j][None], world - col.obj_pos[j])[0]
    size = col.obj_size[j]
    if kind == 0:
        return _box_sd(local, size)
    if kind == 1:
        q = np.stack([np.linalg.norm(local[:, :2], axis=-1) - size[0], np.abs(local[:, 2]) - size[1] / 2], axis=-1)
        return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
    return np.linalg.norm(local, axis=-1) - size[0]


def test_room_kernel_is_room_collision_distances_included():
    rng = np.random.default_rng(2)
    for r in range(3):
        col = RoomCollision(generate_room(np.random.default_rng(r)))
        lo, hi = (np.asarray(b) for b in col.room.bounds())
        n = 20000
        states = np.zeros((n, 13))
        states[:, :3] = rng.uniform(lo - 0.5, hi + 0.5, (n, 3))
        q = rng.normal(size=(n, 4))
        states[:, 3:7] = q / np.sqrt((q * q).sum(axis=1, keepdims=True))
        states[::10, 3:7] = [0.0, 0.0, 0.0, 1.0]
        want = col.states_failed(states)
        args = col.kernel_args()
        got = room_states_failed(states, *args, np.empty(n, dtype=bool))
        assert np.array_equal(got, want) and 0.05 < want.mean() < 0.95
        rot = np.empty(9)
        points, walls, kinds, pos, obj_R, size = args[:6]
        for s in states[:20]:
            x, y, z, w = s[3:7]
            rot[:] = (
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)]
                + [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)]
                + [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]
            )
            shapes = [(-1, j) for j in range(len(walls))] + [(int(kinds[j]), j) for j in range(len(pos))]
            for kind, j in shapes[:: max(1, len(shapes) // 12)]:
                mine = [
                    room_shape_distance(*s[:3], rot, points, p, kind, j, walls, pos, obj_R, size)
                    for p in range(len(points))
                ]
                assert np.array_equal(_bits(mine), _bits(_numpy_room_distances(col, s, kind, j))), (kind, j)


# ---------------------------------------------------------------------------- the scenes' fused levels
def _same_level(scene, states, controls, horizon, n_steps, all_ends=True):
    f1, e1 = scene.propagate_failed(states, controls, horizon, n_steps)
    f2, e2 = SceneBase.propagate_failed(scene, states, controls, horizon, n_steps)
    assert np.array_equal(f1, f2)
    keep = slice(None) if all_ends else ~f1
    assert np.array_equal(_bits(e1[keep]), _bits(e2[keep]))
    return f1.mean()


@pytest.mark.parametrize(
    "dynamics",
    [Dubins4D(), Dubins4D(v_min=0.0, v_max=1.0, u1_min=-0.0, u1_max=0.0, u2_min=-1.0, u2_max=0.0)],
    ids=["default", "zero-width"],
)
def test_dubins4d_fused_level_is_propagate_then_path_failed(dynamics):
    rng = np.random.default_rng(3)
    scene = Dubins4DScene(_circles(rng, 9), np.array([0.0, 0.0, 1.0]), dynamics)
    states, controls = _dubins4d_inputs(rng, 20000)
    for horizon, n_steps in ((2.0, 8), (1.0, 5), (4.0, 16), (7.3, 9), (0.5, 2)):
        assert 0 < _same_level(scene, states, controls, horizon, n_steps) < 1
    _same_level(scene, states[:500], controls[:500], 3.0, 140)
    assert bk._SERIES_MAX == d4._SERIES_MAX and np.array_equal(np.array(bk._C), d4.SERIES_COEFFICIENTS)


def test_maze_fused_level_is_propagate_then_path_failed():
    rng = np.random.default_rng(4)
    scene = MazeScene(generate_maze(rng, rows=8, cols=8), Dubins3D())
    n = 20000
    states = np.column_stack(
        [rng.uniform(-20, scene.maze.width + 20, n), rng.uniform(-20, scene.maze.height + 20, n), rng.uniform(-7, 7, n)]
    )
    states[::7, 0], states[::11, 2] = 0.0, 0.0
    controls = rng.uniform(-0.3, 0.3, (n, 1))
    controls[::5], controls[::6] = 0.2, -0.0
    for horizon, n_steps in ((2.0, 8), (1.0, 3), (4.0, 16), (30.0, 9)):
        assert 0 < _same_level(scene, states, controls, horizon, n_steps) < 1


@pytest.mark.parametrize("command", [True, False], ids=["commands", "thrust"])
def test_quadrotor_fused_level_is_propagate_then_path_failed(command):
    rng = np.random.default_rng(5)
    room = generate_room(np.random.default_rng(6))
    ctl = CommandController()
    scene = QuadrotorCommandScene(room, ctl) if command else QuadrotorScene(room, ctl.params)
    lo, hi = (np.asarray(b) for b in room.bounds())
    n = 300
    states = np.zeros((n, 13))
    states[:, :3] = rng.uniform(lo, hi, (n, 3))
    states[:, 2] = rng.uniform(0.3, 2.5, n)
    states[:, 6] = 1.0
    states[:, 7:10] = rng.uniform(-1, 1, (n, 3))
    controls = rng.uniform(scene.control_low, scene.control_high, (n, 4))
    # a failed branch's ends row is unspecified in the fused loop (it stops at the failing point)
    assert 0 < _same_level(scene, states, controls, 1.0, 5, all_ends=False) < 1


def test_a_subclass_that_changes_the_path_test_is_not_bypassed():
    class Walled(Dubins4DScene):
        def path_failed(self, paths):
            return super().path_failed(paths) | (np.abs(paths[..., 0]) > 3).any(axis=1)

    rng = np.random.default_rng(7)
    scene = Walled(_circles(rng, 3), np.array([0.0, 0.0, 1.0]))
    states, controls = _dubins4d_inputs(rng, 2000)
    f, _ = scene.propagate_failed(states, controls, 2.0, 8)
    assert np.array_equal(f, scene.path_failed(scene.propagate(states, controls, 2.0, 8)))


# ---------------------------------------------------------------------------- the estimator
def test_uniform_box_is_numpys_uniform():
    for lo, hi in (
        ([-0.25, -0.5], [0.25, 0.5]),
        ([-0.2], [0.2]),
        ([-2.0, -2, -1, -1], [2.0, 2, 1, 1]),
        ([0.0, -0.0], [0.0, 1e300]),
    ):
        lo, hi = np.array(lo), np.array(hi)
        a, b = np.random.default_rng(3), np.random.default_rng(3)
        for size in ((64, 1024, lo.size), (5, 32, lo.size), (0, 32, lo.size)):
            assert np.array_equal(_bits(a.uniform(lo, hi, size=size)), _bits(uniform_box(b, lo, hi, size)))
        assert a.random() == b.random()  # the generator left in the same state
    with pytest.raises(ValueError):  # numpy's refusals are numpy's
        uniform_box(np.random.default_rng(0), np.array([1.0]), np.array([0.0]), (2, 1))
    legacy = np.random.RandomState(0)
    assert np.array_equal(
        uniform_box(legacy, np.zeros(2), np.ones(2), (3, 2)), np.random.RandomState(0).uniform(0, 1, (3, 2))
    )


def _labelled(scene, states, **kw):
    out = []
    for fused in (True, False):
        est = RiskEstimator(scene, fused=fused, **kw)
        out.append(est.estimate(states, np.random.default_rng(11)))
    (a, b) = out
    for name in ("risk", "min_risk_ctrl", "min_risk_ctrl_dur", "n_leaves"):
        assert np.array_equal(_bits(getattr(a, name)), _bits(getattr(b, name))), name
    return a


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"metric": "cvar", "alpha": 0.3, "branches": 10},
        {"leaf": "heuristic", "depth": 3, "branches": 6},
        {"chunk_size": 7, "n_steps": 16},
    ],
    ids=["paper", "cvar", "heuristic", "chunks"],
)
def test_fused_labels_are_the_reference_labels_dubins4d(kw):
    rng = np.random.default_rng(8)
    scene = Dubins4DScene(_circles(rng, 6), np.array([0.0, 0.0, 1.0]))
    states, _ = _dubins4d_inputs(rng, 96)
    states[:, :2] *= 0.8
    res = _labelled(scene, states, **kw)
    assert 0 < res.risk.mean() < 1


def test_fused_labels_are_the_reference_labels_maze_quadrotor_and_candidates():
    rng = np.random.default_rng(9)
    maze = MazeScene(generate_maze(rng, rows=8, cols=8))
    states = np.column_stack(
        [rng.uniform(0, maze.maze.width, 64), rng.uniform(0, maze.maze.height, 64), rng.uniform(-3, 3, 64)]
    )
    assert 0 < _labelled(maze, states).risk.mean() < 1
    quad = QuadrotorCommandScene(generate_room(np.random.default_rng(6)), CommandController())
    lo, hi = (np.asarray(b) for b in quad.room.bounds())
    qs = np.zeros((6, 13))
    qs[:, :2] = rng.uniform(lo[:2], hi[:2], (6, 2))
    qs[:, 2], qs[:, 6] = 1.0, 1.0
    assert 0 <= _labelled(quad, qs, branches=4, depth=2, horizon=1.0, n_steps=5).risk.mean() <= 1
    cands = [[0.0, 0.0], [0.25, -0.5], [-0.25, 0.5]]
    scene = Dubins4DScene(_circles(rng, 6), np.array([0.0, 0.0, 1.0]))
    s4, _ = _dubins4d_inputs(rng, 40)
    risks = [
        RiskEstimator(scene, branches=8, fused=f).estimate_candidates(s4, cands, 1.0, np.random.default_rng(2))
        for f in (True, False)
    ]
    assert np.array_equal(_bits(risks[0]), _bits(risks[1]))
