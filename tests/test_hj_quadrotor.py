"""``hj`` on the quadrotor: the horizontal 4-D value at the route's altitude band (rmm_guardians.hj.quadrotor)."""

import math

import numpy as np
import pytest

import rmm_envs  # noqa: F401
from rmm_envs.systems.quadrotor.guarded import QuadrotorRoomGuardedEnv
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rooms import Room
from rmm_guardians import make_guardian
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.grid import Grid
from rmm_guardians.hj.guardian import HJGuardian, HJPaperGuardian
from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian
from rmm_guardians.hj.room import lag_prediction, room_target
from rmm_guardians.hj.solver import solve_brt

# one wall box 4 m high whose face is the plane x = 0 (x from 0 to 1, y from -5 to 5), a far wall
# at x = -12 (the walls' extent bounds the grids), and a sphere
WALL = (0.5, 0.0, 2.0, 0.5, 5.0, 2.0)
FAR = (-11.75, 0.0, 2.0, 0.25, 5.0, 2.0)
SPHERE = {"shape": "sphere", "pos": [-4.0, 3.0, 0.6], "quat": [0.0, 0.0, 0.0, 1.0], "size": [0.6]}


def room(objects=(SPHERE,), walls=(WALL, FAR)) -> Room:
    return Room(
        footprint=np.ones((20, 20), bool),
        origin=np.array([-8.0, -5.0]),
        cell=0.5,
        wall_height=4.0,
        walls=np.array(walls, float).reshape(-1, 6),
        objects=list(objects),
    )


def state(x, y, z=1.0, vx=0.0, vy=0.0):
    s = np.zeros(13)
    s[:3], s[6], s[7], s[8] = (x, y, z), 1.0, vx, vy
    return s


@pytest.fixture(scope="module")
def space():
    return QuadrotorRoomGuardedEnv().action_space


def reset(g, space, st, rm=None, waypoints=((-6.0, -3.0, 1.0),), t=0.0):
    box = {
        "state": st,
        "room": rm or room(),
        "waypoints": np.array(waypoints, float),
        "goal": np.array(waypoints[-1]),
        "sim_time": t,
    }
    g.reset(seed=0, action_space=space, privileged=lambda: box)
    return box


@pytest.fixture(scope="module")
def solved(space, tmp_path_factory):
    g = QuadrotorHJGuardian(cache_dir=tmp_path_factory.mktemp("hjq"), threads=1)
    box = reset(g, space, state(-3.0, 0.0))
    return g, box


def test_room_target_hand_computed():
    grid = Grid([-6.0, -2.0, -math.pi, 0.0], [2.0, 6.0, math.pi, 3.0], [17, 17, 4, 3], periodic=[2])
    T = room_target(grid, room(), 0.5, 1.5)[..., 0, 0]
    at = lambda x, y: T[int(round((x + 6) / 0.5)), int(round((y + 2) / 0.5))]  # noqa: E731
    assert at(-2.0, 0.0) == pytest.approx(2.0 - BOUND, abs=1e-6)  # 2 m from the wall's face
    assert at(0.5, 0.0) == pytest.approx(-0.5 - BOUND, abs=1e-6)  # inside the wall, 0.5 m deep
    # the sphere (radius 0.6, centre at height 0.6): levels every 0.1 m from 0.5 to 1.5, the
    # nearest at its centre's height, 2 m away; less half the level spacing (0.05)
    assert at(-4.0, 1.0) == pytest.approx(2.0 - 0.6 - 0.05 - BOUND, abs=1e-6)
    assert T.dtype == np.float32 and at(-6.0, -2.0) > 2.0
    # a band above the sphere and the wall: nothing in it
    high = room_target(
        grid, room(walls=[(0.5, 0.0, 0.25, 0.5, 5.0, 0.25), (-11.75, 0.0, 0.1, 0.25, 5.0, 0.1)]), 1.5, 2.0
    )
    assert np.all(high == np.float32(1e3 - BOUND))


def test_value_sign_hand_known_cases(solved):
    g, _ = solved
    V = lambda x, vx=0.0, vy=0.0, y=0.0: float(g.evaluate(x, y, vx, vy)[0])  # noqa: E731
    assert V(0.3) < 0  # inside the wall
    assert V(-3.0) > 2.0  # far from it, still
    assert V(-0.8) > 0.3  # 0.8 m away, still: safe
    # 0.8 m away at 3 m/s toward the wall: braking takes 3^2 / (2 * 2.5) = 1.8 m
    assert V(-0.8, vx=3.0) < 0
    # the same speed away from the wall: safe
    assert V(-0.8, vx=-3.0) > 0.3
    assert np.all(g.V <= room_target(g.grid, room(), *g.z_band) + 1e-5)  # the tube only grows


def test_solver_matches_braking_distance():
    # a wall at x >= 0, the velocity straight at it, turning disabled (u1 ~ 0): the closest the
    # point can be kept is d - v^2 / (2 a) (brake at a from v)
    a = 2.5
    grid = Grid([-4.0, -1.0, -math.pi, 0.0], [1.0, 1.0, math.pi, 2.0], [51, 5, 8, 21], periodic=[2])
    target = np.broadcast_to((-grid.coord(0)).astype(np.float32), grid.shape)
    dyn = Dubins4DHJ(u1_max=1e-6, u2_max=a, v_min=0.0, v_max=2.0)
    V, _ = solve_brt(grid, dyn, np.ascontiguousarray(target), 1.0, threads=1)
    for d, v in ((2.0, 2.0), (2.0, 1.0), (1.5, 1.6), (3.0, 0.0)):
        assert grid.interp(V, np.array([-d, 0.0, 0.0, v])) == pytest.approx(d - v * v / (2 * a), abs=0.06)


def test_lag_prediction_closed_form():
    p, v = lag_prediction(1.0, 2.0, 0.0, 2.5, 0.4)
    e = math.exp(-1.0)
    assert v == pytest.approx(2.0 * e) and p == pytest.approx(1.0 + 2.0 * (1 - e) / 2.5)
    assert lag_prediction(0.0, 1.5, 1.5, 2.5, 3.0) == pytest.approx((4.5, 1.5))  # at the reference: straight on


def test_cache_round_trip_and_tampered_entry(space, tmp_path):
    g = QuadrotorHJGuardian(cache_dir=tmp_path, threads=1, spacing=0.5, n_heading=8, n_speed=4, horizon=1.0)
    reset(g, space, state(-3.0, 0.0))
    V = g.V.copy()
    assert g.stats()["solves"] == 1
    reset(g, space, state(-3.0, 0.0))
    assert g.stats()["cache_hits"] == 1 and np.array_equal(g.V, V)
    (entry,) = tmp_path.glob("*.npz")
    z = dict(np.load(entry))
    z["V"] = z["V"] + np.float32(1.0)  # an edited value under the same name
    np.savez(entry, **z)
    with pytest.warns(RuntimeWarning, match="does not match its recorded checksum"):
        reset(g, space, state(-3.0, 0.0))
    assert g.stats()["solves"] == 1 and g.stats()["cache_rejected"] == 1 and np.array_equal(g.V, V)


def test_rule_acts_one_lap_ahead(solved, space):
    g, box = solved
    # 1.2 m from the wall at 1.5 m/s toward it, the pilot pushing on at 1.5 m/s; the value there
    # is near the closed form 1.2 - 0.304 - 1.5^2 / (2 * 2.5) = 0.446
    h0 = (-1.2, 0.0, 1.5, 0.0)
    box["state"], box["sim_time"] = state(-1.2, 0.0, vx=1.5), 0.0
    push = {"nominal_control": np.array([1.5, 0.0, 0.0, 0.0])}
    now = float(g.evaluate(*h0)[0])
    assert now == pytest.approx(1.2 - BOUND - 1.5**2 / 5.0, abs=0.06)
    h1 = g.predict(h0, push["nominal_control"], 1.0, 0.0, 0.1)  # the pending lap (0.1 s before any is measured)
    h2 = g.predict(h1, push["nominal_control"], 1.0, 0.0, 0.1)  # and the lap the decision governs
    assert now > float(g.evaluate(*h1)[0]) > g._margin >= float(g.evaluate(*h2)[0])  # only the latency makes it act
    a = g.act(None, push)
    assert a["active_ctrl"] == 1 and float(a["vforward_ctrl"][0]) < 1.5  # slows down (forward is +x at yaw 0)
    assert float(a["yawrate_ctrl"][0]) == 0.0 and float(a["vup_ctrl"][0]) == 0.0  # the pilot's vertical, no yaw
    g.delay = 0  # without the pending lap it would still wait
    box["sim_time"] = 0.1
    g._held = None
    box["state"] = state(-1.2, 0.0, vx=1.5)
    assert g.act(None, push)["active_ctrl"] == 0
    g.delay = 1
    # far from everything the pilot keeps control
    box["state"] = state(-4.0, -3.0, vx=1.0)
    g._held = None
    assert g.act(None, {"nominal_control": np.array([1.0, 0.0, 0.0, 0.0])})["active_ctrl"] == 0


def test_bad_input_named(solved, space):
    g, box = solved
    box["state"] = state(-3.0, 0.0)
    with pytest.raises(ValueError, match="needs info\\['nominal_control'\\]"):
        g.act(None, {})
    with pytest.raises(ValueError, match="four finite numbers"):
        g.act(None, {"nominal_control": [1.0, np.nan, 0.0, 0.0]})
    for kw, msg in (
        ({"spacing": 0.0}, "spacing must be a finite number > 0"),
        ({"n_speed": 2}, "n_speed must be an integer >= 3"),
        ({"accel": -1.0}, "accel must be"),
        ({"cfl": 2.0}, "cfl must be in"),
        ({"order": 3}, "order must be 1 or 2"),
        ({"n_directions": 3}, "n_directions must be an integer >= 4"),
        ({"min_speed": 0.0}, "min_speed must be"),
        ({"clear_time": -0.1}, "clear_time must be"),
        ({"side_memory": float("nan")}, "side_memory must be"),
        ({"pad": -1.0}, "pad must be"),
    ):
        with pytest.raises(ValueError, match=msg):
            QuadrotorHJGuardian(**kw)
    with pytest.raises(ValueError, match="quadrotor must be a dict"):
        HJGuardian(quadrotor="yes")
    with pytest.raises(ValueError, match="needs a room with walls"):
        reset(QuadrotorHJGuardian(cache=False), space, state(-3.0, 0.0), rm=room(walls=[]))
    # NaN state: the safe default (hover), counted
    box["state"] = state(np.nan, 0.0)
    a = g.act(None, {"nominal_control": np.zeros(4)})
    assert a["active_ctrl"] == 1 and g.stats()["nan_states"] == 1
    # outside the altitude band: left to the pilot, counted
    box["state"] = state(-3.0, 0.0, z=5.0)
    assert g.act(None, {"nominal_control": np.zeros(4)})["active_ctrl"] == 0 and g.stats()["outside_band"] == 1


def test_dispatch_by_spaces(space):
    from rmm_envs.systems.maze.guarded import Dubins3DMazeGuardedEnv

    HJGuardian().check_spaces(None, space)  # the quadrotor: applies
    with pytest.raises(ValueError, match="hj-paper.*Dubins4D envs only"):
        HJPaperGuardian().check_spaces(None, space)
    maze = Dubins3DMazeGuardedEnv().action_space
    with pytest.raises(ValueError, match="models the quadrotor's velocity command"):
        QuadrotorHJGuardian().check_spaces(None, maze)


def test_fixed_clock_episode_the_pilot_crashes(tmp_path):
    import gymnasium as gym

    from rmm_guardians.baselines import InactiveGuardian

    def run(g, seed=2110268680):  # episode 10 of rmm-bench --seed 5 (a development seed)
        env = gym.make("QuadrotorRoomParallel-v0", clock="fixed:1")
        obs, info = env.reset(seed=seed)
        g.reset(
            seed=seed,
            observation_space=env.observation_space,
            action_space=env.action_space,
            privileged=env.unwrapped.privileged,
        )
        while True:
            obs, r, te, tr, info = env.step(g.act(obs, info))
            if te or tr:
                return info["outcome"], info["episode_stats"]

    assert run(InactiveGuardian())[0] == "collision"
    g = make_guardian("hj", env_id="QuadrotorRoomParallel-v0", cache_dir=tmp_path, threads=1)
    outcome, stats = run(g)
    assert outcome == "goal" and stats["n_active_ctrl_env_steps"] > 0
    # one value per leg, and one more over the arrival band of each leg climbing or descending more than 2 band_margin
    q = g.delegate
    assert [len(v) for v in q._legs] == [
        1 + (v[0][0][1] - v[0][0][0] - 2 * q.band_margin > 2 * q.band_margin) for v in q._legs
    ]
    assert g.stats()["solves"] == sum(len(v) for v in q._legs) == 4


def _world(cmd):
    """A heading-frame command at yaw 0 is the world command itself."""
    return float(cmd[0]), float(cmd[1])


def test_turns_to_the_safe_command_nearest_the_pilots(solved):
    g, box = solved
    # 0.9 m from the wall's face (x = 0), moving at it at 1 m/s; the pilot commands 1.5 m/s 10
    # degrees to the right of head-on: turning clockwise (toward -y) reaches a safe command in
    # fewer steps of 2 pi / 16 than turning counter-clockwise
    h1 = (-0.9, 0.0, 1.0, 0.0)
    a = math.radians(-10.0)
    nominal = np.array([1.5 * math.cos(a), 1.5 * math.sin(a), 0.2, 0.5])
    g._side, g._turn, g._last_turn, g._hit = None, 0, None, math.inf  # nearer the waypoint than at the takeover

    def safe(k, side):
        ang = a + side * k * 2 * math.pi / 16
        h = g.predict(h1, (1.5 * math.cos(ang), 1.5 * math.sin(ang)), 1.0, 0.0, 0.1)
        return g.inside(*h) and float(g.evaluate(*h)[0]) > g._margin

    first = {side: next(k for k in range(16) if safe(k, side)) for side in (1.0, -1.0)}
    assert first[-1.0] < first[1.0] and not safe(0, 1.0)  # head-on is unsafe; clockwise is nearer
    cmd = g._choose(h1, nominal, 1.0, 0.0, 0.1)
    ang = a - first[-1.0] * 2 * math.pi / 16
    assert _world(cmd) == pytest.approx((1.5 * math.cos(ang), 1.5 * math.sin(ang)), abs=1e-12)
    assert cmd[2] == pytest.approx(0.2) and cmd[3] == 0.0  # the pilot's vertical, no yaw
    assert g._side == -1.0 and g._turn == first[-1.0]
    # held: the turn comes back toward the pilot's command one step a lap (from 3 steps past
    # the nearest safe one to 2), on the same side
    g._turn = first[-1.0] + 3
    cmd2 = g._choose(h1, nominal, 1.0, 0.0, 0.1)
    ang = a - (first[-1.0] + 2) * 2 * math.pi / 16
    assert g._side == -1.0 and _world(cmd2) == pytest.approx((1.5 * math.cos(ang), 1.5 * math.sin(ang)), abs=1e-12)
    # a slow pilot is turned at min_speed
    g._side, g._turn = None, 0
    slow = np.array([0.1 * math.cos(a), 0.1 * math.sin(a), 0.0, 0.0])
    assert math.hypot(*_world(g._choose(h1, slow, 1.0, 0.0, 0.1))) == pytest.approx(g.min_speed)
    # side memory: taken over again within side_memory of the last turn, it turns the same way
    g._side, g._turn = None, 0
    g._last_turn = (-0.9, 1.0, 1.0)
    g._choose(h1, nominal, 1.0, 0.0, 0.1)
    assert g._side == 1.0
    g._side, g._last_turn = None, (-0.9, 1.0 + g.side_memory + 0.1, 1.0)
    g._choose(h1, nominal, 1.0, 0.0, 0.1)
    assert g._side == -1.0


def test_hands_back_once_the_pilots_command_stays_safe(solved):
    g, box = solved
    g.delay, g._last_time = 1, None
    # 2 m from the wall at rest, the guardian in control: the pilot's command straight at the
    # wall is safe for the next two laps (value ~1.7 m) but not held for clear_time (1 s) more:
    # 1.2 s at the lag's velocity covers 1.5 (1.2 - (1 - e^-3) / 2.5) = 1.23 m, leaving 0.77 m at
    # 1.5 m/s, a value of 0.77 - 0.304 - 1.5^2 / 5 = 0.02 m < margin
    box["state"], box["sim_time"] = state(-2.0, 0.0), 0.0
    g._held, g._side, g._turn = np.array([0.0, 0.0, 0.0, 0.0]), -1.0, 2
    at = {"nominal_control": np.array([1.5, 0.0, 0.0, 0.0])}
    h2 = g.predict(g.predict((-2.0, 0.0, 0.0, 0.0), (0.0, 0.0), 1.0, 0.0, 0.1), (1.5, 0.0), 1.0, 0.0, 0.1)
    assert float(g.evaluate(*h2)[0]) > g._margin + g.hysteresis
    assert g.act(None, at)["active_ctrl"] == 1 and g._side == -1.0
    # the pilot's command away from the wall: handed back, the side forgotten
    box["state"], box["sim_time"] = state(-2.0, 0.0), 0.1
    g._held = np.array([0.0, 0.0, 0.0, 0.0])
    assert g.act(None, {"nominal_control": np.array([-1.5, 0.0, 0.0, 0.0])})["active_ctrl"] == 0
    assert g._side is None and g._turn == 0 and g._held is None
    # with clear_time 0 only the next two laps count: handed back even toward the wall
    g.clear_time = 0.0
    box["state"], box["sim_time"] = state(-2.0, 0.0), 0.2
    g._held = np.array([0.0, 0.0, 0.0, 0.0])
    assert g.act(None, at)["active_ctrl"] == 0
    g.clear_time = 1.0


def test_arrival_band_drops_what_the_climb_rose_above(space, tmp_path):
    # a leg from 0.5 m up to 1.5 m: its band [0.4, 1.6] reaches the sphere (centre 0.6 m up, radius
    # 0.6 m, top 1.2 m); the arrival band [1.35, 1.65] does not.  At (-4, 1.9), 0.5 m from the sphere
    # at its centre's height: 0.5 - 0.05 - 0.304 = 0.146 m at rest in the leg's band; in the arrival
    # band the nearest is the wall's face 4 m away: 4 - 0.304
    g = QuadrotorHJGuardian(cache_dir=tmp_path, threads=1)
    reset(g, space, state(-4.0, 1.9, z=0.5), waypoints=((-6.0, -3.0, 1.5),))
    assert [v[0] for v in g._legs[0]] == [pytest.approx((0.4, 1.6)), pytest.approx((1.35, 1.65))]
    assert g.z_band == pytest.approx((0.4, 1.6))
    assert float(g.evaluate(-4.0, 1.9, 0.0, 0.0)[0]) == pytest.approx(0.5 - 0.05 - BOUND, abs=0.02)
    g._next_leg(state(-4.0, 1.9, z=1.5 - 1.51 * g.band_margin))  # not yet within 1.5 band_margin
    assert g.z_band == pytest.approx((0.4, 1.6))
    g._next_leg(state(-4.0, 1.9, z=1.5 - 1.49 * g.band_margin))
    assert g.z_band == pytest.approx((1.35, 1.65))
    assert float(g.evaluate(-4.0, 1.9, 0.0, 0.0)[0]) == pytest.approx(4.0 - BOUND, abs=0.02)
    # a leg climbing no more than 2 band_margin has one value only
    reset(g, space, state(-4.0, 1.9, z=1.0), waypoints=((-6.0, -3.0, 1.2),))
    assert len(g._legs[0]) == 1


def test_follows_the_boundary_until_nearer_the_waypoint(solved):
    g, box = solved
    # not nearer the waypoint than at the takeover: the scan starts straight at the obstacle
    # (-grad V) instead of at the pilot's command (here straight away from the wall)
    h1 = (-0.9, 0.0, 1.0, 0.0)
    nominal = np.array([-1.5, 0.0, 0.0, 0.0])
    vals = g.evaluate(*h1)
    base = math.atan2(-float(vals[2]), -float(vals[1]))
    assert abs(base) < 0.05  # the wall's face is the plane x = 0: straight at it is +x
    g._side, g._turn, g._last_turn, g._hit = -1.0, 0, None, 0.0

    def safe(ang):
        h = g.predict(h1, (1.5 * math.cos(ang), 1.5 * math.sin(ang)), 1.0, 0.0, 0.1)
        return g.inside(*h) and float(g.evaluate(*h)[0]) > g._margin

    k = next(k for k in range(16) if safe(base - k * 2 * math.pi / 16))
    assert k > 0  # straight at the wall is unsafe
    ang = base - k * 2 * math.pi / 16
    assert _world(g._choose(h1, nominal, 1.0, 0.0, 0.1)) == pytest.approx(
        (1.5 * math.cos(ang), 1.5 * math.sin(ang)), abs=1e-9
    )
    # nearer than at the takeover: the pilot's command itself, safe here
    g._turn, g._hit = 0, math.inf
    assert _world(g._choose(h1, nominal, 1.0, 0.0, 0.1)) == pytest.approx((-1.5, 0.0), abs=1e-12)
