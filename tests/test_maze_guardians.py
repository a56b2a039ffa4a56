"""The privileged guardians on the maze car: ``hj`` (3-D value over the walls) and ``cbf`` (wall barriers)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv
from rmm_envs.systems.maze.mazes import Maze
from rmm_guardians import make_guardian
from rmm_guardians.cbf import CBFGuardian, CBFPaperGuardian
from rmm_guardians.cbf.maze import MazeCBFGuardian, wall_rows
from rmm_guardians.hj.guardian import HJGuardian, HJPaperGuardian
from rmm_guardians.hj.maze import MazeHJGuardian

WALL = np.array([[-1000.0, 0.0, 1000.0, 0.0]])  # one long flat wall along the x axis


def corridor() -> Maze:
    """Three cells in a row (centres x = 125, 250, 375 at y = 125) inside a closed box: wall
    surfaces at y = 68.75 and 181.25, x = 68.75 and 431.25."""
    walls = [
        (62.5, 62.5, 437.5, 62.5),
        (62.5, 187.5, 437.5, 187.5),
        (62.5, 62.5, 62.5, 187.5),
        (437.5, 62.5, 437.5, 187.5),
    ]
    return Maze(
        np.array(walls),
        width=500.0,
        height=250.0,
        cells=np.array([[125.0, 125.0], [250.0, 125.0], [375.0, 125.0]]),
        passages=np.array([[0, 1], [1, 2]]),
    )


def reset_at(env, guardian, state, goal_cell=2):
    obs, info = env.reset(seed=0, options={"maze": corridor(), "state": state, "goal_cell": goal_cell})
    guardian.reset(
        seed=0,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    return obs, info


def episode(env, guardian, seed):
    obs, info = env.reset(seed=seed)
    guardian.reset(
        seed=seed,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    while True:
        obs, r, te, tr, info = env.step(guardian.act(obs, info))
        if te or tr:
            return info["outcome"]


# ------------------------------------------------------------------ cbf: the barrier rows
def test_wall_rows_hand_computed():
    # car 10 px above the wall (surface at 1 px: half 1, margin 0), speed 10, u_max 0.2 (R = 50)
    heading_in = wall_rows([0.0, 10.0, -math.pi / 2], 10.0, WALL, 1.0, 0.0, 1.0, 0.1)
    B, G, h = (np.asarray(a).reshape(-1)[0] for a in heading_in)
    # n = (0, 1), e = (0, -1): n.e = -1, n.e_perp = 0: B = 9 - 50 (1 - 0); either turn raises |n.e_perp|
    # (the tie takes the left one, sigma = +1): dB/dt = s n.e + R u = -10 + 50 u, so G = -50
    assert B == pytest.approx(-41.0) and G == pytest.approx(-50.0) and h == pytest.approx(-10.0 - 41.0)
    B, G, h = (np.asarray(a).reshape(-1)[0] for a in wall_rows([0.0, 10.0, 0.0], 10.0, WALL, 1.0, 0.0, 1.0, 0.1))
    assert (B, G, h) == (pytest.approx(9.0), 0.0, pytest.approx(9.0))  # along the wall: B = b, nothing to do
    # 30 degrees toward the wall, heading right-down: n.e = -1/2, n.e_perp = cos 30; the turn away is left (+)
    B, G, h = (
        np.asarray(a).reshape(-1)[0] for a in wall_rows([0.0, 40.0, -math.pi / 6], 10.0, WALL, 1.0, 2.0, 1.0, 0.1)
    )
    b = 40.0 - 1.0 - 2.0
    assert B == pytest.approx(b - 50.0 * (1 - math.cos(math.pi / 6)))
    assert G == pytest.approx(-50.0 * 0.5)  # -R sigma (-n.e) with sigma = +1
    assert h == pytest.approx(10.0 * -0.5 + B)
    # the distance (high-order) barrier of the same pose: b'' = s (n.e_perp) u, b' = s n.e
    b2, G2, h2 = (
        np.asarray(a).reshape(-1)[0]
        for a in wall_rows([0.0, 40.0, -math.pi / 6], 10.0, WALL, 1.0, 2.0, 0.1, 0.2, barrier="distance")
    )
    assert b2 == pytest.approx(b) and G2 == pytest.approx(-10.0 * math.cos(math.pi / 6))
    assert h2 == pytest.approx(0.3 * 10.0 * -0.5 + 0.02 * b)


@settings(max_examples=60, deadline=None)
@given(
    y=st.floats(15.0, 200.0),
    psi=st.floats(-math.pi, math.pi),
    u=st.floats(-0.2, 0.2),
    x0=st.floats(-1.0, 1.0).map(lambda f: 1100.0 * f),
)
def test_barrier_rate_matches_the_flow(y, psi, u, x0):
    # the row says dB/dt = (h - p1 B) - G u; compare with B along the exact arc (side and cap regions)
    from rmm_envs.systems.maze.dynamics import Dubins3D

    dt = 1e-4
    B0, G, h = (np.asarray(a).reshape(-1)[0] for a in wall_rows([x0, y, psi], 10.0, WALL, 1.0, 0.0, 1.0, 0.1))
    n = np.array([x0 - np.clip(x0, -1000.0, 1000.0), y])
    ne = float(n @ [math.cos(psi), math.sin(psi)]) / np.linalg.norm(n)
    if abs(ne) < 0.02 or abs(abs(ne) - 1.0) < 0.02:  # the barrier's form switches at n.e = 0 and n.e_perp = 0
        return
    x1, y1, p1 = Dubins3D().propagate(np.array([[x0, y, psi]]), np.array([[u]]), dt, 2)[0, -1]
    B1 = np.asarray(wall_rows([x1, y1, p1], 10.0, WALL, 1.0, 0.0, 1.0, 0.1)[0]).reshape(-1)[0]
    assert (B1 - B0) / dt == pytest.approx((h - 1.0 * B0) - G * u, abs=2e-3)


@settings(max_examples=60, deadline=None)
@given(y=st.floats(8.0, 200.0), psi=st.floats(-math.pi, 0.0))
def test_turning_away_always_satisfies_the_row_outside_the_barrier(y, psi):
    # along a flat wall with B >= 0, the full turn away keeps dB/dt = 0: the row is always feasible
    B, G, h = (np.asarray(a).reshape(-1)[0] for a in wall_rows([0.0, y, psi], 10.0, WALL, 1.0, 2.0, 1.0, 0.1))
    if B < 0:
        return
    sigma = 1.0 if math.cos(psi) >= 0 else -1.0  # n = (0, 1): n.e_perp = cos psi
    assert G * (0.2 * sigma) <= h + 1e-9


# ------------------------------------------------------------------ cbf: the guardian
def test_cbf_on_the_maze_turns_only_when_holding_the_heading_is_unsafe():
    """The default, ``reference="hold"``: it keeps the heading (u = 0) where that is safe."""
    env = Dubins3DMazeGuardedEnv()
    g = make_guardian("cbf", env_id="Dubins3DMazeParallel-v0")
    obs, info = reset_at(env, g, [125.0, 125.0, 0.0])
    assert g.act(obs, info)["active_ctrl"] == 0  # mid-corridor, along it
    obs, info = reset_at(env, g, [380.0, 125.0, 0.0], goal_cell=0)  # facing the end wall 51 px away: B < 0
    a = g.act(obs, info)
    assert a["active_ctrl"] == 1 and abs(float(a["turnrate_ctrl"][0])) == pytest.approx(0.2)
    assert g.stats()["qp_fallbacks"] == 1  # no turn satisfies the row head-on: full turn
    # toward the upper wall (surface y = 181.25) at 1 rad, b = 31.25 - 2: B = 29.25 - 50 (1 - cos 1) = 6.26;
    # dB/dt + B >= 0 needs -10 sin 1 - 50 sin(1) u + B >= 0 (sigma = -1: the turn away is right), u <= -0.0511
    lap = 0.1  # the decision is for the pose one lap ahead (the driver's turn taken as 0): recompute there
    _x, y, psi = 300.0 + 10 * lap * math.cos(1.0), 150.0 + 10 * lap * math.sin(1.0), 1.0  # B needs y only
    B = (181.25 - y - 2.0) - 50.0 * (1 - math.cos(psi))
    obs, info = reset_at(env, g, [300.0, 150.0, 1.0])
    a = g.act(obs, info)
    assert a["active_ctrl"] == 1 and g.stats()["qp_fallbacks"] == 0  # a QP turn, not the fallback
    assert float(a["turnrate_ctrl"][0]) == pytest.approx((B - 10 * math.sin(psi)) / (50 * math.sin(psi)), abs=1e-5)


def test_cbf_on_the_maze_filters_the_drivers_turn_rate():
    """``reference="nominal"`` filters ``info["nominal_control"]``: a nominal turn toward the upper wall
    (surface y = 181.25) is lowered exactly onto the barrier row at the pose predicted under
    it one lap ahead, ``u <= (B - 10 sin psi) / (50 sin psi)`` (the row derived above); a turn
    away from the wall passes to the driver untouched."""
    env = Dubins3DMazeGuardedEnv()
    g = make_guardian("cbf", env_id="Dubins3DMazeParallel-v0", maze={"reference": "nominal"})
    obs, info = reset_at(env, g, [300.0, 150.0, 1.0])
    x, y, psi = g.delegate.predict([300.0, 150.0, 1.0], 0.2, 0.1)  # the driver turns left at 0.2 during the lap
    B = (181.25 - y - 2.0) - 50.0 * (1 - math.cos(psi))
    a = g.act(obs, {**info, "nominal_control": np.array([0.2])})
    assert a["active_ctrl"] == 1
    assert float(a["turnrate_ctrl"][0]) == pytest.approx((B - 10 * math.sin(psi)) / (50 * math.sin(psi)), abs=1e-5)
    obs, info = reset_at(env, g, [300.0, 150.0, 1.0])
    assert g.act(obs, {**info, "nominal_control": np.array([-0.2])})["active_ctrl"] == 0  # turning away: safe
    with pytest.raises(ValueError, match=r"\(maze\) filters the driver's control, info\['nominal_control'\]"):
        g.act(obs, {})
    with pytest.raises(ValueError, match="reference must be one of"):
        MazeCBFGuardian(reference="zero")


def test_cbf_and_hj_avoid_a_collision_the_driver_makes():
    from rmm_guardians.baselines import InactiveGuardian

    env = Dubins3DMazeGuardedEnv()
    assert episode(env, InactiveGuardian(), 1) == "collision"
    assert episode(env, make_guardian("cbf"), 1) == "goal"


def test_cbf_maze_bad_arguments_and_dispatch():
    with pytest.raises(ValueError, match="barrier must be one of"):
        MazeCBFGuardian(barrier="circle")
    with pytest.raises(ValueError, match="n_walls must be an integer >= 1"):
        MazeCBFGuardian(n_walls=0)
    with pytest.raises(ValueError, match="p1"):
        CBFGuardian(maze={"p1": -1.0})
    with pytest.raises(ValueError, match="maze must be a dict"):
        CBFGuardian(maze="yes")
    env = Dubins3DMazeGuardedEnv()
    with pytest.raises(ValueError, match="cbf-paper.*Dubins4D envs only"):
        CBFPaperGuardian().check_spaces(env.observation_space, env.action_space)
    CBFGuardian().check_spaces(env.observation_space, env.action_space)  # the maze car: applies
    three = GuardianActionSpace(("a", "b", "c"), [-1.0] * 3, [1.0] * 3)
    with pytest.raises(ValueError, match="applies to Dubins4D envs and the maze car"):
        CBFGuardian().check_spaces(None, three)
    lopsided = GuardianActionSpace(("turnrate_ctrl",), [-0.1], [0.2], dynamics_name="dubins3d")
    with pytest.raises(ValueError, match="symmetric about 0"):
        CBFGuardian().check_spaces(None, lopsided)


# ------------------------------------------------------------------ hj
@pytest.fixture(scope="module")
def hj_corridor(maze_hj_cache):
    g = HJGuardian(
        maze={"spacing": 10.0, "n_heading": 16, "horizon": 12.0, "region": "maze", "rule": "distance"},
        cache_dir=maze_hj_cache,
        threads=1,
    )
    env = Dubins3DMazeGuardedEnv()
    return env, g


def test_hj_maze_value_and_decisions(hj_corridor):
    env, g = hj_corridor
    obs, info = reset_at(env, g, [125.0, 125.0, 0.0])
    m = g.delegate
    assert (
        isinstance(m, MazeHJGuardian) and m.stats()["solves"] + m.stats()["cache_hits"] == 1
    )  # a cache shared by the session
    V = m.V[..., 0]
    from rmm_guardians.hj.maze import wall_target

    target = wall_target(m.grid, corridor())[..., 0]
    assert np.all(V <= target + 1e-4)  # the tube only grows: never above the distance now
    assert np.all(V[target <= 0] <= 0)  # inside a wall is unsafe
    assert g.act(obs, info)["active_ctrl"] == 0  # mid-corridor along it: safe
    assert m.evaluate([125.0, 125.0, 0.0])[0] > 20.0
    # 30 px from the end wall, heading at it: cannot turn away in time (R = 50 px)
    assert m.evaluate([400.0, 125.0, 0.0])[0] <= 0.0
    # 80 px from it, heading at it: the value falls below the threshold before the turn is too late
    obs, info = reset_at(env, g, [340.0, 125.0, 0.3], goal_cell=0)
    a = g.act(obs, info)
    assert m.stats()["cache_hits"] == 1  # the same maze: read from the cache
    assert a["active_ctrl"] == 1 and float(a["turnrate_ctrl"][0]) == pytest.approx(0.2)  # turns left, as it leans
    # half a position cell (about 10 px) + two 0.1-s laps at 10 px/s
    assert m.threshold() == pytest.approx(0.5 * max(m.grid.dx[:2]) + 10.0 * 2 * 0.1) and 9.5 < max(m.grid.dx[:2]) <= 10
    assert g.stats() == m.stats()


def test_hj_maze_route_region_and_outside_grid(hj_corridor, tmp_path):
    env, _ = hj_corridor
    g = MazeHJGuardian(spacing=10.0, n_heading=16, horizon=4.0, region="route", route_margin=0, cache=False, threads=1)
    obs, info = reset_at(env, g, [125.0, 125.0, 0.0], goal_cell=1)
    # the route is cells 0 and 1: x from 125 - 62.5 to 250 + 62.5, y the cells' row +- 62.5
    assert g.grid.lo[:2].tolist() == [62.5, 62.5] and g.grid.hi[0] >= 312.5 and g.grid.hi[1] >= 187.5
    env.unwrapped._state[:] = [400.0, 125.0, 0.0]  # beyond the route's cells (a test reaches into the env)
    assert g.act(obs, info)["active_ctrl"] == 0 and g.stats()["outside_grid"] == 1


def test_hj_maze_bad_arguments_and_dispatch():
    with pytest.raises(ValueError, match="region must be one of"):
        MazeHJGuardian(region="everywhere")
    with pytest.raises(ValueError, match="spacing must be a finite number > 0"):
        MazeHJGuardian(spacing=0.0)
    with pytest.raises(ValueError, match="n_heading must be an integer >= 3"):
        HJGuardian(maze={"n_heading": 2})
    with pytest.raises(ValueError, match="maze must be a dict"):
        HJGuardian(maze=[1])
    env = Dubins3DMazeGuardedEnv()
    with pytest.raises(ValueError, match="hj-paper.*Dubins4D envs only"):
        HJPaperGuardian().check_spaces(env.observation_space, env.action_space)
    HJGuardian().check_spaces(env.observation_space, env.action_space)
    with pytest.raises(ValueError, match="applies to Dubins4D envs and the maze car"):
        HJGuardian().check_spaces(None, GuardianActionSpace(("a", "b", "c"), [-1.0] * 3, [1.0] * 3))
    g = MazeHJGuardian(cache=False)
    obs, info = env.reset(seed=0)
    no_speed = lambda: {k: v for k, v in env.unwrapped.privileged().items() if k != "speed"}  # noqa: E731
    with pytest.raises(ValueError, match="needs the car's speed"):
        g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space, privileged=no_speed)


# ------------------------------------------------------------------ hj's look-ahead rule
def test_lookahead_manoeuvres_and_path_clearances():
    from rmm_guardians.hj.maze_lookahead import COEF, manoeuvres, path_clearances

    man = manoeuvres(0.2, 6.0)
    loop = 2 * math.pi / 0.2
    assert man.shape == (3 + 5 * 6, 4)
    assert man[:3].tolist() == [[-0.2, 0.0, -0.2, loop], [0.0, 0.0, 0.0, 6.0], [0.2, 0.0, 0.2, loop]]
    straight = man[:, 2] == 0
    assert np.allclose(man[straight, 1] + man[straight, 3], 6.0) and np.all(man[~straight, 3] == loop)
    assert sorted(set(man[:, 1].tolist())) == pytest.approx([0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    m = corridor()
    walls = np.asarray(m.walls, float)
    clear, ends = np.empty(2), np.empty((2, 3))
    # straight along the corridor's centre line from x = 125 for 6 s; a left loop from x = 250
    path_clearances(
        125.0,
        125.0,
        0.0,
        10.0,
        np.array([[0.0, 0.0, 0.0, 6.0]]),
        0.2,
        walls,
        m.half,
        500.0,
        250.0,
        COEF,
        clear[:1],
        ends[:1],
    )
    path_clearances(
        250.0,
        125.0,
        0.0,
        10.0,
        np.array([[0.2, 0.0, 0.2, loop]]),
        0.2,
        walls,
        m.half,
        500.0,
        250.0,
        COEF,
        clear[1:],
        ends[1:],
    )
    # 56.25 px to the side walls' surfaces all along, less half a sample's travel (1 px)
    assert clear[0] == pytest.approx(56.25 - 1.0) and ends[0].tolist() == pytest.approx([185.0, 125.0, 0.0])
    # the loop (radius 50 about (250, 175)) crosses the upper wall (centre line y = 187.5, 6.25 px
    # half-thickness): its deepest sample is within one sample's travel of -6.25, less 1 px
    assert -7.25 <= clear[1] < -5.25 and ends[1][:2] == pytest.approx([250.0, 125.0], abs=1e-6)


def test_hj_maze_lookahead_decisions(maze_hj_cache):
    env = Dubins3DMazeGuardedEnv()
    g = MazeHJGuardian(spacing=10.0, n_heading=16, horizon=12.0, region="maze", cache_dir=maze_hj_cache, threads=1)
    obs, info = reset_at(env, g, [250.0, 125.0, 0.0])
    info = dict(info, nominal_control=np.array([0.0]))
    assert g.act(obs, info)["active_ctrl"] == 0  # mid-corridor along it, the driver straight on: passive
    env.unwrapped._state[:] = [
        380.0,
        125.0,
        0.0,
    ]  # 51 px from the end wall, heading at it (a test reaches into the env)
    a = g.act(obs, info)
    # no loop fits a 112.5-px corridor from its centre line; turning keeps the car off the wall longer
    assert a["active_ctrl"] == 1 and abs(float(a["turnrate_ctrl"][0])) == pytest.approx(0.2)
    with pytest.raises(ValueError, match="needs info\\['nominal_control'\\]"):
        g.act(obs, {})
    with pytest.raises(ValueError, match="one finite turn rate"):
        g.act(obs, {"nominal_control": [np.nan]})
    with pytest.raises(ValueError, match="rule must be one of"):
        MazeHJGuardian(rule="sign")
    with pytest.raises(ValueError, match="lookahead must be a finite number > 0"):
        MazeHJGuardian(lookahead=0.0)
    with pytest.raises(ValueError, match="value_error must be a finite number >= 0"):
        MazeHJGuardian(value_error=-1.0)
    with pytest.raises(ValueError, match="band must be a finite number >= 0"):
        MazeHJGuardian(band=float("nan"))
