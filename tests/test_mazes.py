import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.env import Dubins3DMazeEnv
from rmm_envs.systems.maze.mazes import MAZE_GENERATORS, Maze, _seg_point_sq, generate_maze, render_occupancy
from rmm_envs.wrappers import RiskLabel


def test_quarter_circle_of_radius_r_min():
    sys_ = Dubins3D()  # 10 px/s, R = 50 px, u_max = 0.2
    T = (math.pi / 2) / 0.2
    end = sys_.propagate(np.zeros((1, 3)), np.array([[0.2]]), T, 5)[0, -1]
    np.testing.assert_allclose(end, [50.0, 50.0, math.pi / 2], atol=1e-9)
    straight = sys_.propagate(np.array([[1.0, 2.0, math.pi / 4]]), np.zeros((1, 1)), 3.0, 2)[0, -1]
    np.testing.assert_allclose(straight, [1 + 30 / math.sqrt(2), 2 + 30 / math.sqrt(2), math.pi / 4], atol=1e-12)
    clipped = sys_.propagate(np.zeros((1, 3)), np.array([[5.0]]), 1.0, 2)[0, -1]
    assert clipped[2] == pytest.approx(0.2)


def hand_maze():
    return Maze(np.array([[100.0, 50.0, 100.0, 150.0]]), width=200.0, height=200.0, thickness=10.0)


def test_exact_ray_lengths_in_a_hand_built_maze():
    m = hand_maze()
    r = m.rays(np.array([[50.0, 100.0, 0.0]]))[0]
    assert r[0] == pytest.approx(45.0)  # to the wall's surface at x = 95
    assert r[2] == pytest.approx(100.0)  # up to the border
    assert r[4] == pytest.approx(50.0)  # back to the border
    assert r[1] == pytest.approx(45.0 * math.sqrt(2))  # 45 degrees: x = 95 at y = 145 (within the side)
    # past the end of the segment: the round cap of radius 5 at (100, 150)
    assert m.rays(np.array([[50.0, 153.0, 0.0]]))[0, 0] == pytest.approx(50.0 - 4.0)
    assert m.rays(np.array([[50.0, 160.0, 0.0]]))[0, 0] == pytest.approx(150.0)  # misses the cap
    assert np.all(m.rays(np.array([[100.0, 100.0, 0.3]])) == 0.0)  # inside the wall


def test_path_crossing_cases():
    m = hand_maze()
    paths = np.array(
        [
            [[90.0, 100.0], [110.0, 100.0]],  # straight through the wall, both ends outside it
            [[96.0, 157.0], [104.0, 157.0]],  # cuts the round cap (closest approach 7 > 5? no: 7 from centre)
            [[96.0, 153.0], [104.0, 153.0]],  # cuts the cap: passes 3 px from its centre
            [[50.0, 20.0], [150.0, 20.0]],  # below the wall: clear
            [[150.0, 100.0], [250.0, 100.0]],  # leaves the image
        ]
    )
    assert m.paths_hit(paths).tolist() == [True, False, True, False, True]


walls_st = st.lists(st.tuples(*[st.floats(20, 380)] * 4), min_size=1, max_size=12)


@settings(max_examples=40, deadline=None)
@given(walls=walls_st, seed=st.integers(0, 1000))
def test_pruned_queries_equal_brute_force(walls, seed):
    m = Maze(np.array(walls), width=400.0, height=400.0, thickness=6.0)
    rng = np.random.default_rng(seed)
    pts = rng.uniform(0, 400, (200, 2))
    w = m.walls
    brute = (
        np.sqrt(
            _seg_point_sq(w[None, :, 0], w[None, :, 1], w[None, :, 2], w[None, :, 3], pts[:, 0:1], pts[:, 1:2]).min(1)
        )
        - 3.0
    )
    near = brute < m.reach
    np.testing.assert_allclose(m.point_clearance(pts)[near], brute[near], atol=1e-9)
    # paths of 8 points within 40 px: compare with dense sampling (exact ones may only add hits
    # that fall between samples)
    start = rng.uniform(10, 390, (100, 1, 2))
    steps = np.cumsum(rng.uniform(-2.8, 2.8, (100, 7, 2)), axis=1)
    paths = np.concatenate([start, start + steps], axis=1)
    exact = m.paths_hit(paths)
    dense = np.concatenate(
        [
            paths[:, i : i + 1] + np.linspace(0, 1, 50)[None, :, None] * (paths[:, i + 1 : i + 2] - paths[:, i : i + 1])
            for i in range(7)
        ],
        axis=1,
    )
    sampled = np.array([m.state_failed(p).any() for p in dense])
    assert np.all(exact[sampled])  # every sampled hit is found
    assert np.mean(exact != sampled) < 0.05


@pytest.mark.parametrize("generator", MAZE_GENERATORS)
def test_generated_mazes_are_seeded_and_connected(generator):
    a = generate_maze(np.random.default_rng(5), generator)
    b = generate_maze(np.random.default_rng(5), generator)
    np.testing.assert_array_equal(a.walls, b.walls)
    assert not np.array_equal(a.walls, generate_maze(np.random.default_rng(6), generator).walls)
    for seed in range(5):
        m = generate_maze(np.random.default_rng(seed), generator)
        n = len(m.cells)
        assert len(m.passages) == n - 1  # a spanning tree
        adj = {i: [] for i in range(n)}
        for u, v in m.passages:
            adj[u].append(v)
            adj[v].append(u)
        seen, todo = {0}, [0]
        while todo:
            for v in adj[todo.pop()]:
                if v not in seen:
                    seen.add(v)
                    todo.append(v)
        assert len(seen) == n
        # cell centres are free space; the passage between neighbours is open
        assert not m.state_failed(m.cells).any()
        mid = 0.5 * (m.cells[m.passages[:, 0]] + m.cells[m.passages[:, 1]])
        assert not m.state_failed(mid).any()


def test_default_geometry_and_occupancy():
    m = generate_maze(np.random.default_rng(0))
    assert (m.width, m.height, m.thickness) == (2750.0, 2750.0, 12.5)
    occ = render_occupancy(m, resolution=5.0)  # pixel centres sampled: finer than the 12.5 px walls
    assert occ.shape == (550, 550) and 0.02 < occ.mean() < 0.2


def test_env_checker_and_bad_input():
    check_env(gym.make("Dubins3DMaze-v0").unwrapped)
    env = Dubins3DMazeEnv()
    with pytest.raises(ValueError, match="maze"):
        env.reset(seed=0, options={"maze": "big"})
    m = hand_maze()
    with pytest.raises(ValueError, match="inside a wall"):
        env.reset(seed=0, options={"maze": m, "state": [100.0, 100.0, 0.0]})
    with pytest.raises(ValueError, match="3 finite"):
        env.reset(seed=0, options={"maze": m, "state": [10.0, 10.0]})
    with pytest.raises(ValueError, match="maze_kind"):
        Dubins3DMazeEnv(maze_kind="circular")
    with pytest.raises(ValueError, match="unknown maze generator"):
        generate_maze(np.random.default_rng(0), "circular")
    env.reset(seed=0, options={"maze": m, "state": [50.0, 100.0, 0.0]})
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan]))
    with pytest.raises(ValueError, match="shape"):
        env.step(np.zeros(2))


def test_collision_terminates_and_is_seeded():
    env = Dubins3DMazeEnv()
    env.reset(seed=0, options={"maze": hand_maze(), "state": [50.0, 100.0, 0.0]})
    for k in range(10):
        obs, r, te, tr, info = env.step(np.zeros(1, np.float32))
        if te:
            collided_at = k
            break
    assert te and r == -1.0 and info["outcome"] == "collision" and collided_at == 4  # 45 px at 10 px/s
    a = Dubins3DMazeEnv().reset(seed=3)[0]
    b = Dubins3DMazeEnv().reset(seed=3)[0]
    np.testing.assert_array_equal(a, b)


def test_risk_label_works_on_mazes():
    env = RiskLabel(gym.make("Dubins3DMaze-v0"), branches=8, seed=0)
    _, info = env.reset(seed=0, options={"maze": hand_maze(), "state": [90.0, 20.0, 0.0]})
    assert info["risk"] == 0.0  # heading under the wall's end into open space
    _, info = env.reset(seed=0, options={"maze": hand_maze(), "state": [85.0, 100.0, 0.0]})
    assert info["risk"] == 1.0  # 5 px from the wall, turning radius 50 px


def test_rgb_render():
    env = gym.make("Dubins3DMaze-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (512, 512, 3) and (frame == 0).all(axis=-1).mean() > 0.01


def test_shipped_maze_model():
    from rmm_guardians.lrmm.model import LRMMModel, default_model_path

    m = LRMMModel.load(default_model_path("Dubins3DMaze-v0"), env_id="Dubins3DMaze-v0", obs_dim=8)
    assert m.meta["data"]["n_rows"] >= 65536 + 4096
    assert m.meta["metrics"]["train"]["n"] == 65536 and m.meta["metrics"]["test"]["n"] == 4096
    assert len(m.meta["split"]["test_configs"]) == 2
    assert m.meta["metrics"]["test"]["mae"] <= 0.045
    # a state facing a wall 10 px away is risky; the middle of a long corridor is not
    env = Dubins3DMazeEnv()
    maze = Maze(
        np.array([[0.0, 100.0, 1000.0, 100.0], [0.0, 300.0, 1000.0, 300.0]]), width=1000.0, height=400.0, thickness=12.5
    )
    env.reset(seed=0, options={"maze": maze, "state": [500.0, 200.0, 0.0]})
    open_obs = env.observe_states(np.array([[500.0, 200.0, 0.0]]))
    wall_obs = env.observe_states(np.array([[500.0, 280.0, np.pi / 2]]))
    assert m.predict(wall_obs[0]) > 0.8 > 0.2 > m.predict(open_obs[0])
