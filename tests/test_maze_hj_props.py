"""The maze ``hj`` guardian's decision (``guardians/hj/maze.py``): grid, target, region and the look-ahead rule.

The corridor of ``tests/test_maze_guardians.py`` (three cells in a row, wall surfaces at
y = 68.75 and 181.25, x = 68.75 and 431.25), the car at 10 px/s with ``|u| <= 0.2`` (turning
radius 50 px).  The guardian is reset from a privileged dict, without an env; its value is
solved once into a cache (``$RMM_TEST_HJ_CACHE`` when set, so that ``make mutate`` solves it
once for all mutants).

The look-ahead rule is checked three ways: hand-built poses where the answer is known (passive
along the corridor, straight on rather than the full turn away when the driver turns into a
wall, the full turn when nothing is safe), a reference written from the module docstring
over *every* wall (the guardian prunes the walls out of reach first: pruning must not change a
decision), and the exact geometry: what the guardian leaves to the driver, and the manoeuvre it
commands, keep more than the margin from every wall on the exact arcs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv
from rmm_envs.systems.maze.mazes import Maze
from rmm_guardians.hj.maze import MazeHJGuardian, maze_grid, wall_target
from rmm_guardians.hj.maze_lookahead import COEF, manoeuvres, path_clearances
from tests.test_maze_guardians import corridor
from tests.test_maze_lookahead_props import clearance, exact_path

SPEED, U = 10.0, 0.2
SETTINGS = dict(spacing=10.0, n_heading=16, horizon=12.0, region="maze", threads=1)  # test_maze_guardians.py's grid


@pytest.fixture(scope="module")
def space():
    env = Dubins3DMazeGuardedEnv()
    yield env.action_space
    env.close()


@pytest.fixture(scope="module")
def cache_dir(maze_hj_cache):
    return maze_hj_cache  # tests/conftest.py: one cache for the session (or make mutate's run)


def make(space, cache_dir, state=(250.0, 125.0, 0.0), maze=None, goal=(375.0, 125.0), **kw):
    """A guardian reset on ``maze`` (the corridor) with the car at ``state``; returns it and
    the privileged dict it reads (change ``state`` / ``sim_time`` there to move the car)."""
    priv = {
        "state": np.array(state, float),
        "maze": maze or corridor(),
        "goal": np.array([*goal, 10.0]),
        "speed": SPEED,
        "sim_time": 0.0,
    }
    g = MazeHJGuardian(**{**SETTINGS, "cache_dir": cache_dir, **kw})
    g.reset(seed=0, action_space=space, privileged=lambda: priv)
    return g, priv


def act(g, priv, pose, nominal, t=None):
    priv["state"] = np.array(pose, float)
    if t is not None:
        priv["sim_time"] = t
    a = g.act(np.zeros(3), {"nominal_control": np.array([nominal])})
    return float(a["turnrate_ctrl"][0]) if a["active_ctrl"] else None


# ------------------------------------------------------------------ grid, target, region
def test_maze_grid_hand_computed():
    g = maze_grid([0.0, 10.0], [95.0, 30.0], 10.0, 8, 10.0)
    # ceil(95 / 10) + 1 = 11 nodes in x; ceil(20 / 10) + 1 = 3 in y; 8 periodic headings; 3 speeds
    assert list(g.n) == [11, 3, 8, 3] and list(g.periodic) == [False, False, True, False]
    assert g.lo.tolist() == [0.0, 10.0, -math.pi, 10.0] and g.hi.tolist() == [95.0, 30.0, math.pi, 10.0 + 1e-5]
    assert g.dx[0] == pytest.approx(9.5) and g.dx[1] == pytest.approx(10.0) and g.dx[2] == pytest.approx(math.pi / 4)
    small = maze_grid([0.0, 0.0], [5.0, 41.0], 10.0, 3, 1.0)  # at least 3 nodes; ceil(4.1) + 1 = 6
    assert list(small.n) == [3, 6, 3, 3]


def test_wall_target_is_the_signed_distance_at_every_node():
    m = corridor()
    g = maze_grid([62.5, 50.0], [462.5, 200.0], 25.0, 4, 10.0)
    t = wall_target(g, m)
    assert t.dtype == np.float32 and t.shape == tuple(g.n)
    X, Y = np.meshgrid(g.axes[0], g.axes[1], indexing="ij")
    d = clearance(np.column_stack([X.ravel(), Y.ravel()]), np.asarray(m.walls, float), m.half).reshape(X.shape)
    want = np.minimum(d, m.reach)  # the maze reports its reach at least beyond it
    for k in range(4):
        for j in range(3):
            np.testing.assert_allclose(t[:, :, k, j], want, atol=1e-4)
    assert t[0, 4, 0, 0] == pytest.approx(-6.25) and t[4, 3, 0, 0] == pytest.approx(
        56.25
    )  # (62.5, 150) on a wall's centre line; (162.5, 125)


def square_maze() -> Maze:
    """Four cells (2 x 2, centres 125 and 250 px) in a closed box 62.5-312.5, a tree of passages 0-1, 1-3, 0-2."""
    walls = [
        (62.5, 62.5, 312.5, 62.5),
        (62.5, 312.5, 312.5, 312.5),
        (62.5, 62.5, 62.5, 312.5),
        (312.5, 62.5, 312.5, 312.5),
        (187.5, 187.5, 312.5, 187.5),
    ]
    cells = [[125.0, 125.0], [250.0, 125.0], [125.0, 250.0], [250.0, 250.0]]
    return Maze(
        np.array(walls), width=400.0, height=400.0, cells=np.array(cells), passages=np.array([[0, 1], [1, 3], [0, 2]])
    )


def test_region_box_hand_computed():
    g = MazeHJGuardian(route_margin=0, cache=False)
    m = square_maze()
    # cells 0 -> 1: x from 125 - 62.5 to 250 + 62.5, y the bottom row's +- 62.5
    lo, hi = g.region_box(m, np.array([120.0, 130.0, 0.0]), np.array([255.0, 120.0, 10.0]))
    assert lo.tolist() == [62.5, 62.5] and hi.tolist() == [312.5, 187.5]
    # cells 2 -> 3 go round the inner wall: 2, 0, 1, 3, the whole box
    lo, hi = g.region_box(m, np.array([125.0, 250.0, 0.0]), np.array([250.0, 250.0, 10.0]))
    assert lo.tolist() == [62.5, 62.5] and hi.tolist() == [312.5, 312.5]
    # cells 0 -> 2 with one cell of margin: 1.5 cells (187.5 px) round the column, clipped to the walls
    lo, hi = MazeHJGuardian(route_margin=1, cache=False).region_box(
        m, np.array([125.0, 125.0, 0.0]), np.array([125.0, 250.0, 10.0])
    )
    assert lo.tolist() == [62.5, 62.5] and hi.tolist() == [312.5, 312.5]
    lo, hi = g.region_box(m, np.array([125.0, 125.0, 0.0]), np.array([125.0, 250.0, 10.0]))
    assert lo.tolist() == [62.5, 62.5] and hi.tolist() == [187.5, 312.5]
    # cells 1 -> 3, a column: x is the column's +- 62.5 (not the smaller y of the route's cells)
    lo, hi = g.region_box(m, np.array([250.0, 125.0, 0.0]), np.array([250.0, 250.0, 10.0]))
    assert lo.tolist() == [187.5, 62.5] and hi.tolist() == [312.5, 312.5]
    # the walls' extent takes each coordinate from both ends of every wall
    rails = Maze(np.array([[0.0, 10.0, 100.0, 10.0], [0.0, 50.0, 100.0, 50.0]]), width=200.0, height=200.0)
    lo, hi = MazeHJGuardian(region="maze", cache=False).region_box(rails, np.zeros(3), np.zeros(3))
    assert lo.tolist() == [0.0, 10.0] and hi.tolist() == [100.0, 50.0]
    # region "maze", and a maze of one cell: the walls' extent
    for guardian, maze in (
        (MazeHJGuardian(region="maze", cache=False), m),
        (g, Maze(m.walls, width=400.0, height=400.0, cells=np.array([[125.0, 125.0]]))),
    ):
        lo, hi = guardian.region_box(maze, np.array([125.0, 125.0, 0.0]), np.array([250.0, 125.0, 10.0]))
        assert lo.tolist() == [62.5, 62.5] and hi.tolist() == [312.5, 312.5]


# ------------------------------------------------------------------ reset and the value
def test_reset_reads_the_car_and_the_value(space, cache_dir):
    g, priv = make(space, cache_dir)
    assert g.u_max == U and g.speed == SPEED and g.stats()["solves"] + g.stats()["cache_hits"] == 1
    assert g.grid.lo[:2].tolist() == [62.5, 62.5] and g.grid.hi[:2].tolist() == [437.5, 187.5]
    assert g._margin == pytest.approx(0.5 * max(g.grid.dx[0], g.grid.dx[1]))
    # at a node the value and its heading derivative are the arrays' own; between two nodes, between them
    i, j, k = 9, 6, 5
    node = [g.grid.axes[0][i], g.grid.axes[1][j], g.grid.axes[2][k]]
    vals = g.evaluate(node)
    assert vals[0] == pytest.approx(float(g.V[i, j, k, 0]), abs=1e-5)
    dpsi = (g.V[i, j, k + 1, 0] - g.V[i, j, k - 1, 0]) / (2 * g.grid.dx[2])
    assert vals[3] == pytest.approx(float(dpsi), abs=1e-4)
    mid = g.evaluate([node[0] + 0.5 * g.grid.dx[0], node[1], node[2]])[0]
    assert mid == pytest.approx(0.5 * float(g.V[i, j, k, 0] + g.V[i + 1, j, k, 0]), abs=1e-4)
    assert g.evaluate([250.0, 125.0, 0.0])[0] > 20.0  # mid-corridor along it: far from every wall's reach
    # the same maze again: the cache; an explicit margin is used as given
    g2, _ = make(space, cache_dir, margin=1.5)
    assert g2.stats() == {"outside_grid": 0, "nan_states": 0, "cache_hits": 1, "solves": 0, "solve_seconds": 0.0}
    assert g2._margin == 1.5 and g2.threshold() == pytest.approx(1.5 + SPEED * 2 * 0.1)
    for backend in ("numba", "numpy"):  # checked against the grid and the dynamics at reset (the value is cached)
        assert make(space, cache_dir, backend=backend)[0].stats()["cache_hits"] == 1
    # the value's turn rate is the action space's bound (a coarse, short solve)
    wide = GuardianActionSpace(("turnrate_ctrl",), [-0.3], [0.3], dynamics_name="dubins3d")
    g3 = MazeHJGuardian(spacing=25.0, n_heading=8, horizon=2.0, region="maze", cache=False, threads=1)
    g3.reset(seed=0, action_space=wide, privileged=lambda: priv)
    assert g3.u_max == 0.3 and g3.dynamics.u1_max == 0.3 and g3.dynamics.u2_max == 0.0
    assert g3.dynamics.v_min == g3.dynamics.v_max == SPEED
    priv["maze"] = Maze(np.zeros((0, 4)), width=500.0, height=250.0)
    with pytest.raises(ValueError, match="needs a maze with walls, got none"):
        g.reset(seed=0, action_space=space, privileged=lambda: priv)
    priv["maze"], priv["speed"] = corridor(), 0.0
    with pytest.raises(ValueError, match="privileged speed must be a finite number > 0"):
        g.reset(seed=0, action_space=space, privileged=lambda: priv)


def test_lap_is_measured_from_the_simulated_time(space, cache_dir):
    g, priv = make(space, cache_dir, rule="distance", delay=2)
    assert g.current_lap() == 0.1  # nothing measured yet
    act(g, priv, (250.0, 125.0, 0.0), 0.0, t=1.0)
    act(g, priv, (250.0, 125.0, 0.0), 0.0, t=1.25)
    assert g.current_lap() == pytest.approx(0.25)
    assert g.threshold() == pytest.approx(g._margin + SPEED * 3 * 0.25)  # (1 + delay) laps of travel
    act(g, priv, (250.0, 125.0, 0.0), 0.0, t=1.25)  # time not moving on: the last lap stays
    assert g.current_lap() == pytest.approx(0.25)
    g3, priv3 = make(space, cache_dir, rule="distance", lap=0.5, delay=0)
    act(g3, priv3, (250.0, 125.0, 0.0), 0.0, t=1.0)
    act(g3, priv3, (250.0, 125.0, 0.0), 0.0, t=1.1)
    assert g3.current_lap() == 0.5 and g3.threshold() == pytest.approx(g3._margin + SPEED * 0.5)


# ------------------------------------------------------------------ act: edge cases and the distance rule
def test_nan_pose_applies_the_safe_default_and_outside_the_grid_is_left_alone(space, cache_dir):
    env = Dubins3DMazeGuardedEnv()
    obs, _ = env.reset(seed=0, options={"maze": corridor(), "state": [250.0, 170.0, 0.0], "goal_cell": 2})
    env.close()
    g, priv = make(space, cache_dir)
    priv["state"] = np.array([np.nan, 125.0, 0.0])
    a = g.act(obs, {"nominal_control": np.array([0.0])})
    # 11 px under the upper wall heading along it: the nearer wall is on the left, so turn right
    assert a["active_ctrl"] == 1 and float(a["turnrate_ctrl"][0]) == -U and g.stats()["nan_states"] == 1
    assert act(g, priv, (30.0, 125.0, 0.0), 0.2) is None and g.stats()["outside_grid"] == 1
    assert act(g, priv, (250.0, 195.0, 0.0), 0.2) is None and g.stats()["outside_grid"] == 2  # above the grid
    g.reset(seed=0, action_space=space, privileged=lambda: priv)
    assert g.stats()["outside_grid"] == 0 and g.stats()["nan_states"] == 0


@settings(max_examples=40, deadline=None)
@given(st.floats(75.0, 425.0), st.floats(75.0, 175.0), st.floats(-4.0, 4.0))
@example(340.0, 125.0, 0.3)
def test_distance_rule_acts_below_the_threshold_turning_up_the_value(space, cache_dir, distance_guardian, x, y, psi):
    g, priv = distance_guardian
    u = act(g, priv, (x, y, psi), 0.0)
    wrapped = (psi + math.pi) % (2 * math.pi) - math.pi
    V, _, _, dpsi = g.evaluate((x, y, wrapped))
    if V <= g.threshold():
        assert u == (U if dpsi >= 0 else -U)
    else:
        assert u is None


@pytest.fixture(scope="module")
def distance_guardian(space, cache_dir):
    return make(space, cache_dir, rule="distance")


# ------------------------------------------------------------------ the look-ahead rule by hand
def test_lookahead_hand_built_cases(space, cache_dir):
    g, priv = make(space, cache_dir)
    # mid-corridor along it, the driver straight on: passive (far beyond the band: nothing scored)
    assert act(g, priv, (250.0, 125.0, 0.0), 0.0) is None
    # 5.25 px under the upper wall heading along it: less than the margin (4.93 px) plus half a
    # sample's travel (1 px), so no manoeuvre is certified from here; the best-scoring one is
    # the right loop (it clears the lower wall by 7.25 px, the start is the closest point), whatever the driver does
    assert g._margin == pytest.approx(0.5 * 375.0 / 38) and act(g, priv, (150.0, 176.0, 0.0), U) == -U
    g, priv = make(space, cache_dir)
    assert act(g, priv, (150.0, 176.0, 0.0), -U) == -U
    g, priv = make(space, cache_dir)
    assert act(g, priv, (150.0, 171.0, 0.0), -U) is None  # 5 px lower, the driver turning away: passive
    # 31 px from the end wall heading at it: no manoeuvre keeps the margin (turns need 50 px);
    # the best-scoring one is a full turn
    g, priv = make(space, cache_dir)
    assert abs(act(g, priv, (400.0, 125.0, 0.0), 0.0)) == U
    # the least invasive certified manoeuvre: the driver's right turn keeps the margin, so the
    # guardian keeps that turn though a left turn would score higher
    g, priv = make(space, cache_dir)
    assert act(g, priv, (200.2, 161.46, -1.9058), -U) == -U
    want, _, scores = reference(g, 200.2, 161.46, -1.9058, -U, None)
    first = manoeuvres(U, 6.0)[int(np.argmax(scores))]
    assert want == -U and (first[0] if first[1] > 0 else first[2]) == U
    # a lap of 2 s: the lap under way starts 3.75 px from the wall (within the margin plus a
    # sample's slack), so the guardian is not passive though the car heads away from the wall
    g, priv = make(space, cache_dir, lap=2.0)
    assert (
        act(g, priv, (150.0, 171.25, -math.pi / 2), 0.0) == reference(g, 150.0, 171.25, -math.pi / 2, 0.0, None)[0] == U
    )
    # band 0: where the value is positive the guardian leaves the driver alone without a look-ahead
    # (V = 5.2 px 5.25 px under the wall, where the look-ahead would turn right), unless it holds control
    g, priv = make(space, cache_dir, band=0.0)
    assert g.evaluate((150.0, 176.0, 0.0))[0] > 0 and act(g, priv, (150.0, 176.0, 0.0), U) is None
    assert g.evaluate((400.0, 125.0, 0.0))[0] <= 0 and abs(act(g, priv, (400.0, 125.0, 0.0), 0.0)) == U
    assert act(g, priv, (150.0, 176.0, 0.0), U) == -U  # held control: the look-ahead decides
    assert act(g, priv, (250.0, 125.0, 0.0), 0.0) is None  # handed back mid-corridor
    assert g.act(np.zeros(3), {"nominal_control": 0.0})["active_ctrl"] == 0  # one plain number is a turn rate too
    with pytest.raises(ValueError, match=r"needs info\['nominal_control'\] from the env \(got keys NoneType\)"):
        g.act(np.zeros(3), None)
    with pytest.raises(ValueError, match="must be one finite turn rate, got"):
        g.act(np.zeros(3), {"nominal_control": [0.1, 0.2]})


# ------------------------------------------------------------------ the look-ahead rule: reference and exact geometry
def reference(g, x, y, psi, nominal, held):
    """The module docstring's rule over every wall of the maze, in plain loops."""
    if not g.grid.contains([x, y, psi, g.speed]):
        return None, None, None
    walls, half, width, height = g._maze_geom
    lap, s, margin = g.current_lap(), g.speed, g._margin

    def run(pose, rows, dt):
        clear, ends = np.empty(len(rows)), np.empty((len(rows), 3))
        path_clearances(*pose, s, np.asarray(rows, float), dt, walls, half, width, height, COEF, clear, ends)
        return clear, ends

    def scores(pose):
        rows = manoeuvres(g.u_max, g.lookahead)
        clear, ends = run(pose, rows, 0.2)
        for m, (_u1, _t1, u2, _t2) in enumerate(rows):
            end = ends[m].copy()
            end[2] = (end[2] + math.pi) % (2 * math.pi) - math.pi
            if u2 == 0.0 and clear[m] > 0 and g.grid.contains([*end, s]):
                clear[m] = min(clear[m], g.evaluate(end)[0] - g.value_error)
        return clear, [u1 if t1 > 0 else u2 for u1, t1, u2, t2 in rows]

    u0 = nominal if held is None else held
    if g.delay:
        c0, e = run((x, y, psi), [[u0, 0.0, u0, lap * g.delay]], min(0.2, lap * g.delay))
        p1 = tuple(e[0])
    else:
        c0, p1 = [math.inf], (x, y, psi)
    c1, e = run(p1, [[nominal, 0.0, nominal, lap]], min(0.2, lap))
    if min(c0[0], c1[0], scores(tuple(e[0]))[0].max()) > margin:
        return None, p1, None
    sc, first = scores(p1)
    safe = [m for m in range(len(sc)) if sc[m] > margin]
    if not safe:
        return first[int(np.argmax(sc))], p1, sc
    nearest = min(abs(first[m] - nominal) for m in safe)
    return first[max((m for m in safe if abs(first[m] - nominal) <= nearest + 1e-12), key=lambda m: sc[m])], p1, sc


@pytest.fixture(scope="module", params=[1, 0, 2, "route"], ids=["delay1", "delay0", "delay2", "route"])
def lookahead_guardian(request, space, cache_dir):
    if request.param == "route":  # a grid over cells 0 and 1 only: manoeuvres end beyond it
        return make(space, cache_dir, band=60.0, region="route", route_margin=0, goal=(250.0, 125.0))
    return make(space, cache_dir, delay=request.param, band=60.0)  # a wide band: the rule runs almost everywhere


@settings(max_examples=30, deadline=None)
@given(
    st.floats(75.0, 425.0),
    st.floats(72.0, 178.0),
    st.floats(-math.pi, math.pi),
    st.sampled_from([-U, 0.0, U, 0.07]),
    st.sampled_from([None, -U, 0.0, U]),
)
@example(150.0, 161.25, 0.0, U, None)
@example(380.0, 125.0, 0.2, 0.0, U)
@example(290.0, 120.0, 0.1, 0.0, None)  # straight manoeuvres end beyond the route's grid
def test_lookahead_matches_the_rule_and_keeps_the_margin_on_the_exact_arcs(
    lookahead_guardian, x, y, psi, nominal, held
):
    g, priv = lookahead_guardian
    g._pending = held  # the turn rate commanded at the previous step (None: the guardian was passive)
    u = act(g, priv, (x, y, psi), nominal)
    want, p1, sc = reference(g, x, y, psi, nominal, held)
    assert u == want
    if p1 is None:  # outside the grid: left to the driver
        return
    lap, margin = g.current_lap(), g._margin
    u0 = nominal if held is None else held
    fine = []
    if g.delay:
        fine.append(exact_path(x, y, psi, (u0, 0.0, u0, lap * g.delay), 0.005))
    if u is None:  # what is left to the driver keeps the margin: the lap under way and one more of the driver's
        fine.append(exact_path(*p1, (nominal, 0.0, nominal, lap), 0.005))
        assert clearance(np.vstack(fine), g._maze_geom[0], g._maze_geom[1]).min() > margin
        return
    if sc.max() > margin:  # a certified manoeuvre exists: one that starts with the turn taken keeps the margin
        rows = manoeuvres(U, g.lookahead)
        first = np.where(rows[:, 1] > 0, rows[:, 0], rows[:, 2])
        kept = [
            clearance(exact_path(*p1, rows[m], 0.05), g._maze_geom[0], g._maze_geom[1]).min()
            for m in range(len(rows))
            if sc[m] > margin and first[m] == u
        ]
        assert kept and min(kept) > margin


def test_a_lopsided_or_foreign_action_space_is_refused(cache_dir):
    g = MazeHJGuardian(cache_dir=cache_dir)
    priv = {
        "state": np.array([250.0, 125.0, 0.0]),
        "maze": corridor(),
        "goal": np.array([375.0, 125.0, 10.0]),
        "speed": SPEED,
        "sim_time": 0.0,
    }
    with pytest.raises(ValueError, match="symmetric about 0"):
        g.reset(
            seed=0,
            action_space=GuardianActionSpace(("turnrate_ctrl",), [-0.1], [0.2], dynamics_name="dubins3d"),
            privileged=lambda: priv,
        )
