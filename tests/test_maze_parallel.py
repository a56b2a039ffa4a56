"""Dubins3DMazeGuarded-v0 / Dubins3DMazeParallel-v0: driver, contract, bad input, guardians."""

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import rmm_envs  # noqa: F401
from rmm_bench.cli import main as bench_main
from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.dubins4d.dynamics import SERIES_COEFFICIENTS
from rmm_envs.systems.maze.driver import PursuitDriver, cell_distances, cell_path
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv, TurnFromNearerWall, observation_layout
from rmm_envs.systems.maze.maze_kernels import dubins_path, maze_path_hit, maze_rays
from rmm_envs.systems.maze.mazes import Maze, generate_maze
from rmm_guardians import make_guardian
from rmm_guardians.baselines import BrakesGuardian

EPISODE_KEYS = {
    "outcome",
    "n_env_steps",
    "n_active_ctrl_env_steps",
    "active_ctrl_sim_time",
    "cum_sim_time",
    "cum_compute_time",
    "avg_compute_time",
    "cum_reward",
    "cum_cost",
    "final_speed",
}


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


def run(env, actions, **reset):
    obs, info = env.reset(**reset)
    out = [obs]
    while True:
        obs, r, te, tr, info = env.step(actions(obs))
        out.append(obs)
        if te or tr:
            return np.array(out), r, info


# ------------------------------------------------------------------ the driver
def test_cell_path_and_distances_follow_the_passages():
    m = corridor()
    assert cell_path(m, 0, 2) == [0, 1, 2] and cell_path(m, 2, 0) == [2, 1, 0]
    assert cell_distances(m, 0).tolist() == [0, 1, 2]
    with pytest.raises(ValueError, match="goal cell must be in"):
        cell_path(m, 0, 3)


def test_pure_pursuit_hand_checked():
    d = PursuitDriver(0.2, lookahead=50.0, gain=1.0)
    d.reset([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    assert d.target(0.0, 0.0) == (50.0, 0.0) and d.control([0.0, 0.0, 0.0]) == 0.0
    assert d.control([0.0, 0.0, 0.1]) == pytest.approx(-0.1)  # gain x bearing error, unsaturated
    assert d.control([0.0, 0.0, math.pi / 2]) == -0.2  # saturated at u_max
    d.reset([[0.0, 0.0], [100.0, 0.0], [100.0, 100.0]])
    assert d.target(90.0, 0.0) == pytest.approx((100.0, 40.0))  # 50 px on, around the corner: cut it
    assert d.control([90.0, 0.0, 0.0]) == 0.2
    assert d.target(100.0, 10.0) == pytest.approx((100.0, 60.0))  # on the second segment now
    assert d.target(10.0, 0.0) == pytest.approx((100.0, 50.0))  # progress does not run back to the first
    assert d.target(100.0, 90.0) == (100.0, 100.0)  # past the end: the goal centre
    with pytest.raises(ValueError, match="lookahead"):
        PursuitDriver(0.2, lookahead=0.0)
    with pytest.raises(ValueError, match="waypoints"):
        d.reset([[0.0, 0.0]])


def test_driver_drives_straight_to_the_goal_hand_counted():
    env = Dubins3DMazeGuardedEnv()
    obs, r, info = run(
        env,
        lambda o: env.action_space.inactive(),
        seed=0,
        options={"maze": corridor(), "state": [125.0, 125.0, 0.0], "goal_cell": 2},
    )
    # 1 px per step along y = 125: the path's end reaches x = 345, 30 px from the goal, on step 220
    assert info["outcome"] == "goal" and r == 1.0 and info["episode_stats"]["n_env_steps"] == 220
    assert info["episode_stats"]["cum_sim_time"] == pytest.approx(22.0) and info["episode_stats"]["cum_reward"] == 1.0
    assert info["episode_stats"]["n_active_ctrl_env_steps"] == 0 and info["episode_stats"]["final_speed"] == 10.0


def test_driver_turns_toward_its_path_and_guardian_overrides():
    env = Dubins3DMazeGuardedEnv()
    env.reset(seed=0, options={"maze": corridor(), "state": [125.0, 125.0, math.pi / 2], "goal_cell": 2})
    _, _, _, _, info = env.step(env.action_space.inactive())
    assert info["control"].tolist() == [-0.2] and not info["active"]  # 90 degrees off: full right turn
    _, _, _, _, info = env.step(env.action_space.active([0.7]))
    assert info["control"].tolist() == [pytest.approx(0.2)] and info["active"]  # clipped to the bound


def test_collision_hand_counted():
    env = Dubins3DMazeGuardedEnv()
    _, r, info = run(
        env,
        lambda o: env.action_space.active([0.0]),
        seed=0,
        options={"maze": corridor(), "state": [125.0, 125.0, math.pi / 2], "goal_cell": 2},
    )
    # straight up from y = 125 at 1 px per step: the wall's surface y = 181.25 is crossed on step 57
    assert info["outcome"] == "collision" and r == -1.0 and info["episode_stats"]["n_env_steps"] == 57
    assert info["episode_stats"]["n_active_ctrl_env_steps"] == 57 and info["episode_stats"][
        "active_ctrl_sim_time"
    ] == pytest.approx(5.7)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(env.action_space.inactive())


def test_driver_alone_collides_often_under_a_fixed_clock():
    env = gym.make("Dubins3DMazeParallel-v0", clock="fixed:1")
    outcomes = [run(env, lambda o: env.action_space.inactive(), seed=s)[2]["outcome"] for s in range(48)]
    assert outcomes.count("collision") / len(outcomes) >= 0.2  # the bar (measured ~0.4)
    assert outcomes.count("goal") / len(outcomes) >= 0.3  # careless, not hopeless


# ------------------------------------------------------------------ the contract
@pytest.mark.parametrize("env_id", ["Dubins3DMazeGuarded-v0", "Dubins3DMazeParallel-v0"])
def test_check_env_spaces_and_last_step_info(env_id):
    env = gym.make(env_id, clock="fixed:1")
    check_env(env.unwrapped, skip_render_check=True)
    space = env.action_space
    assert isinstance(space, GuardianActionSpace) and space.controls == ("turnrate_ctrl",)
    assert space.control_low.tolist() == [pytest.approx(-0.2)] and space.control_high.tolist() == [pytest.approx(0.2)]
    assert isinstance(space.safe_default, TurnFromNearerWall)
    lay = env.observation_space.layout
    assert lay.names == ("rays", "goal_offset", "heading") and lay.size == 11
    assert lay.ray_angles == tuple(k * math.pi / 4 for k in range(8))
    _, _, info = run(env, lambda o: space.inactive(), seed=3)
    assert set(info["episode_stats"]) == EPISODE_KEYS and info["outcome"] in ("goal", "collision", "timeout")
    assert info["episode_stats"]["outcome"] == info["outcome"]


def test_observation_fields_match_the_maze_env_and_the_pose():
    env = Dubins3DMazeGuardedEnv()
    obs, info = env.reset(seed=11)
    x, y, psi = info["state"]
    lay = observation_layout()
    ref = env.scene.maze.rays(info["state"][None], 8)[0].astype(np.float32)
    assert np.array_equal(obs[lay["rays"]], ref)
    assert obs[lay["goal_offset"]].tolist() == pytest.approx([env.goal[0] - x, env.goal[1] - y], rel=1e-6)
    assert obs[lay.index("heading")] == pytest.approx(psi, rel=1e-6) and -math.pi <= psi < math.pi
    assert np.array_equal(env.observe_states(info["state"][None])[0], obs)


def test_kernels_equal_the_numpy_maze_queries():
    rng = np.random.default_rng(4)
    m = generate_maze(rng, "rectangular", 6, 6)
    st = np.column_stack([rng.uniform(0, m.width, 300), rng.uniform(0, m.height, 300), rng.uniform(-np.pi, np.pi, 300)])
    ref = m.rays(st, 8)
    out = np.empty(8)
    for i in range(st.shape[0]):
        assert np.array_equal(
            maze_rays(m.walls, m.half, m.width, m.height, st[i, 0], st[i, 1], st[i, 2], 8, out), ref[i]
        )
    u = rng.uniform(-0.2, 0.2, 300)
    paths = Dubins3D().propagate(st, u, 3.0, 8)
    hits = np.array([maze_path_hit(m.walls, m.half, m.width, m.height, p) for p in paths])
    assert np.array_equal(hits, m.paths_hit(paths)) and 0.1 < hits.mean() < 0.9
    for i in range(20):
        mine = dubins_path(st[i, 0], st[i, 1], st[i, 2], 10.0, u[i], 3.0, np.empty((8, 3)), SERIES_COEFFICIENTS)
        np.testing.assert_allclose(mine, paths[i], rtol=0, atol=1e-9)


def test_same_seed_same_episode():
    a, b = (gym.make("Dubins3DMazeParallel-v0", clock="fixed:1") for _ in range(2))
    ta, ra, ia = run(a, lambda o: a.action_space.inactive(), seed=21)
    tb, rb, ib = run(b, lambda o: b.action_space.inactive(), seed=21)
    assert np.array_equal(ta, tb) and ia["episode_stats"] == ib["episode_stats"]
    o1, _ = a.reset(seed=22)
    o2, _ = a.reset(seed=23)
    assert not np.array_equal(o1, o2)


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize(
    "options, match",
    [
        ({"goal": 1}, "unknown reset options"),
        ({"maze": "big"}, "option 'maze' must be"),
        ({"maze": {"generator": "round"}}, "unknown maze generator"),
        ({"maze": "corridor", "state": [125.0, 65.0, 0.0]}, "inside a wall"),
        ({"maze": "corridor", "state": [20.0, 20.0, 0.0]}, "outside the maze's cells"),
        ({"maze": "corridor", "state": [125.0, 125.0]}, "option 'state' must be 3 finite numbers"),
        ({"maze": "corridor", "state": [125.0, 125.0, math.nan]}, "option 'state'"),
        ({"maze": "corridor", "state": [125.0, 125.0, 0.0], "goal_cell": 0}, "other than the start cell 0"),
        ({"maze": "corridor", "goal_cell": 3}, r"goal_cell' must be an integer cell index in \[0, 3\)"),
        ({"maze": "corridor", "goal_cell": 1.5}, "goal_cell"),
        ({"maze": "corridor"}, "no cell of the maze is 4-8 passages"),
    ],
)
def test_bad_reset_options(options, match):
    env = Dubins3DMazeGuardedEnv()
    if options.get("maze") == "corridor":
        options = {**options, "maze": corridor()}
    with pytest.raises(ValueError, match=match):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"goal_cells": (5, 3)}, "goal_cells"),
        ({"goal_cells": 4}, "goal_cells"),
        ({"step_dt": 0.0}, "step_dt"),
        ({"heading_noise": 4.0}, "heading_noise"),
        ({"lookahead": -1.0}, "lookahead"),
        ({"maze_rows": 1}, "maze_rows"),
        ({"max_episode_sim_time": math.inf}, "max_episode_sim_time"),
        ({"render_mode": "human"}, "render_mode"),
        ({"clock": "sundial"}, "clock"),
    ],
)
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Dubins3DMazeGuardedEnv(**kwargs)


@pytest.mark.parametrize(
    "action, match",
    [
        ({"active_ctrl": 1}, "missing field 'turnrate_ctrl'"),
        ({"active_ctrl": 2, "turnrate_ctrl": [0.0]}, "0 or 1"),
        ({"active_ctrl": 1, "turnrate_ctrl": [math.nan]}, "finite"),
        ({"active_ctrl": 1, "turnrate_ctrl": [0.0], "accel_ctrl": [0.0]}, "unknown fields"),
    ],
)
def test_bad_actions_refused_before_the_world_moves(action, match):
    env = gym.make("Dubins3DMazeParallel-v0", clock="fixed:1")
    env.reset(seed=0)
    before = env.unwrapped.true_state
    with pytest.raises(ValueError, match=match):
        env.step(action)
    assert np.array_equal(env.unwrapped.true_state, before)


# ------------------------------------------------------------------ guardians
def test_safe_default_turns_away_from_the_nearer_wall():
    env = Dubins3DMazeGuardedEnv()
    space = env.action_space
    policy = space.safe_default.policy(space, np.random.default_rng(0))
    near_left = np.array([50, 10, 50, 50, 50, 50, 50, 50, 0, 0, 0], np.float32)  # ray 1 (+45 deg) shortest
    near_right = np.array([50, 50, 50, 50, 50, 50, 50, 10, 0, 0, 0], np.float32)  # ray 7 (-45 deg) shortest
    assert policy(near_left).tolist() == [pytest.approx(-0.2)] and policy(near_right).tolist() == [pytest.approx(0.2)]
    assert policy(np.full(11, 50, np.float32)).tolist() == [pytest.approx(0.2)]  # a tie: left
    env.reset(seed=0, options={"maze": corridor(), "state": [125.0, 100.0, 0.0], "goal_cell": 2})  # bottom wall nearer
    g = make_guardian("brakes")
    obs, _ = env.reset(seed=0, options={"maze": corridor(), "state": [125.0, 100.0, 0.0], "goal_cell": 2})
    g.reset(seed=0, observation_space=env.observation_space, action_space=space)
    assert space.parse(g.act(obs, {})) == (True, pytest.approx(np.array([0.2])))
    with pytest.raises(ValueError, match="takes no option.*turn"):
        BrakesGuardian(turn="zero").reset(seed=0, observation_space=env.observation_space, action_space=space)
    with pytest.raises(ValueError, match="states none"):
        BrakesGuardian().reset(seed=0, action_space=GuardianActionSpace(("turnrate_ctrl",), [-1.0], [1.0]))


def test_lrmm_reads_the_maze_model_on_the_rays_and_turns_to_the_lower_risk_side():
    env = Dubins3DMazeGuardedEnv()
    from rmm_guardians.lrmm.strategies import Commit, RayTurn

    default = make_guardian("lrmm", env_id="Dubins3DMazeParallel-v0")
    assert default.model.env_id == "Dubins3DMaze-v0" and default.inputs == "rays"
    assert (default.threshold, default.strategies) == (0.7, (Commit(steps=5),))  # RayTurn removed by its ablation
    g = make_guardian("lrmm", env_id="Dubins3DMazeParallel-v0", strategies="+RayTurn")
    assert g.strategies == (Commit(steps=5), RayTurn(rate=None))
    obs, _ = env.reset(seed=0, options={"maze": corridor(), "state": [125.0, 125.0, 0.0], "goal_cell": 2})
    g.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    assert g.act(obs, {})["active_ctrl"] == 0 and g.last_risk < 0.7  # mid-corridor, heading along it
    obs, _ = env.reset(seed=0, options={"maze": corridor(), "state": [125.0, 160.0, math.pi / 2 - 0.4], "goal_cell": 2})
    rays = obs[:8].astype(float)
    r_left, r_right = g.model.predict(np.stack([np.roll(rays, -1), np.roll(rays, 1)]))
    action = g.act(obs, {})
    assert g.last_risk > 0.7 and action["active_ctrl"] == 1 and r_right < r_left  # heading up-right, wall ahead
    assert action["turnrate_ctrl"].tolist() == [pytest.approx(-0.2)]  # so: turn right, along the corridor
    moved = obs.copy()
    moved[8:] = [1e4, -1e4, 0.0]  # the model reads the rays only
    assert g.act(moved, {}) == action
    default.reset(seed=0, observation_space=env.observation_space, action_space=env.action_space)
    assert default.act(obs, {}) == action  # the safe default (away from the nearer wall) turns the same way


def test_rmm_bench_refuses_a_named_guardian_that_does_not_apply(tmp_path, capsys):
    for agent in ("cbf-paper", "hj-paper"):  # the paper's rules are Dubins4D's only
        assert (
            bench_main(
                [
                    "--env",
                    "Dubins3DMazeParallel-v0",
                    "--agent",
                    agent,
                    "--episodes",
                    "1",
                    "--workers",
                    "1",
                    "--out",
                    str(tmp_path),
                    "--no-progress",
                ]
            )
            == 2
        )
        err = capsys.readouterr().err
        assert f"--agent {agent} does not apply to --env Dubins3DMazeParallel-v0" in err and "Dubins4D envs only" in err


def test_rmm_bench_set_runs_what_applies_and_lists_the_rest(tmp_path, capsys):
    import sqlite3

    assert (
        bench_main(
            [
                "--env",
                "Dubins3DMazeParallel-v0",
                "--agent",
                "paper",
                "--episodes",
                "1",
                "--workers",
                "1",
                "--out",
                str(tmp_path),
                "--no-progress",
                "--no-figure",
                "--clock",
                "fixed:1",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    for agent in ("cbf-paper", "hj-paper"):
        assert (
            f"--agent paper: {agent} does not apply to --env Dubins3DMazeParallel-v0, skipped: guardian {agent!r} "
            "applies to Dubins4D envs only"
        ) in err
    con = sqlite3.connect(tmp_path / "results.db")
    ran = {r[0] for r in con.execute("select agent from runs")}
    con.close()
    assert "lrmm-paper does not apply to --env Dubins3DMazeParallel-v0, skipped: cannot be built for it" in err
    assert ran == {"random", "inactive", "brakes"}


def test_safe_default_contract_and_dubins4d_braking():
    from rmm_envs.systems.dubins4d.dynamics import FullBraking

    with pytest.raises(TypeError, match="SafeDefault"):
        GuardianActionSpace(("turnrate_ctrl",), [-1.0], [1.0], safe_default="brake")
    space = gym.make("Dubins4DParallel-v0").action_space
    assert isinstance(space.safe_default, FullBraking)
    u = space.safe_default.policy(space, np.random.default_rng(5))(None)
    assert u[1] == -0.5 and u[0] == np.random.default_rng(5).uniform(-0.25, 0.25)  # the draw brakes always made
    assert space.safe_default.policy(space, np.random.default_rng(5), turn="zero")(None).tolist() == [0.0, -0.5]
    with pytest.raises(ValueError, match=r"takes no option\(s\) \['spin'\]"):
        space.safe_default.policy(space, np.random.default_rng(5), spin=1)
    with pytest.raises(ValueError, match="turn must be"):
        space.safe_default.policy(space, np.random.default_rng(5), turn="left")


def test_make_guardian_passes_env_id_only_to_guardians_that_take_it():
    assert make_guardian("inactive", env_id="Dubins3DMazeParallel-v0").name == "inactive"
    assert make_guardian("lrmm", env_id="Dubins4DParallel-v0").model.env_id != "Dubins3DMaze-v0"
    with pytest.raises(ValueError, match=r"no shipped LRMM model for 'Dubins3DMazeParallel-v0' \(variant 'paper'\)"):
        make_guardian("lrmm-paper", env_id="Dubins3DMazeParallel-v0")
    with pytest.raises(ValueError, match="env_id must be"):
        make_guardian("lrmm", env_id=3)
    g = make_guardian("lrmm", env_id="Dubins4DParallel-v0")  # the Dubins4D model on the maze's spaces: refused by name
    env = Dubins3DMazeGuardedEnv()
    with pytest.raises(ValueError, match=r"guardian 'lrmm'.*shape \(17,\)"):
        g.check_spaces(env.observation_space, env.action_space)
