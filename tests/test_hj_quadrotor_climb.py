"""``hj`` on the quadrotor climbs over what blocks the way (rmm_guardians.hj.quadrotor_climb): when it
climbs, to what height, that it never descends onto an obstacle, and its refused options."""

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rmm_envs  # noqa: F401
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rooms import Room
from rmm_envs.systems.quadrotor.rotations import quat_from_euler
from rmm_guardians import make_guardian
from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian
from rmm_guardians.hj.quadrotor_climb import DESCEND, SETTLE, Climb, ClimbPlan
from rmm_guardians.hj.room import object_top, room_distance

CLEAR = BOUND + 0.15  # the body's bounding radius and the default climb_margin


def corridor(height=1.2, objects=()):
    """A room 21 m x 10.5 m (x from -8.5 to 12.5, y from -5.25 to 5.25) closed by walls 4 m high,
    cut across by a wall ``height`` m high at x from 0 to 1: no way round it."""
    walls = [
        (0.5, 0.0, height / 2, 0.5, 5.0, height / 2),
        (2.0, 5.25, 2.0, 10.5, 0.25, 2.0),
        (2.0, -5.25, 2.0, 10.5, 0.25, 2.0),
        (-8.75, 0.0, 2.0, 0.25, 5.5, 2.0),
        (12.75, 0.0, 2.0, 0.25, 5.5, 2.0),
    ]
    return Room(
        footprint=np.ones((41, 21), bool),
        origin=np.array([-8.5, -5.25]),
        cell=0.5,
        wall_height=4.0,
        walls=np.array(walls, float),
        objects=list(objects),
    )


def fly(room, opts, cache_dir, t_max=25.0):
    """One episode of ``QuadrotorRoomGuarded-v0`` from (-3, 0, 1) at rest to the goal (5, 0, 1) under
    ``hj`` with ``quadrotor=opts``: its outcome, the highest and the closest the body came to the room
    (the exact distance from the body's centre) and the guardian's counts."""
    env = gym.make("QuadrotorRoomGuarded-v0", max_episode_sim_time=t_max)
    s0 = np.zeros(13)
    s0[:3], s0[6] = (-3.0, 0.0, 1.0), 1.0
    obs, info = env.reset(seed=0, options={"room": room, "state": s0, "waypoints": [[5.0, 0.0, 1.0]]})
    g = make_guardian("hj", env_id="QuadrotorRoomGuarded-v0", cache_dir=cache_dir, threads=1, quadrotor=opts)
    g.reset(
        seed=0,
        observation_space=env.observation_space,
        action_space=env.action_space,
        privileged=env.unwrapped.privileged,
    )
    path = []
    while True:
        obs, _, te, tr, info = env.step(g.act(obs, info))
        path.append(info["state"][:3])
        if te or tr:
            env.close()
            path = np.array(path)
            return info["outcome"], path[:, 2].max(), float(room_distance(room, path).min()), g.stats()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("hjclimb")


def test_climbs_over_a_low_wall_the_value_cannot_pass(cache):
    # the pilot alone flies into the wall; the value alone follows it for the whole episode (no
    # way round); the climb rises to the wall's top (1.2 m) + 0.304 + 0.15 + SETTLE and passes
    outcome, z_max, gap, stats = fly(corridor(1.2), {"climb_after": None}, cache)
    assert outcome == "timeout" and z_max < 1.2 and stats["climbs"] == 0
    outcome, z_max, gap, stats = fly(corridor(1.2), {}, cache)
    assert outcome == "goal" and stats["climbs"] == 1 and stats["climb_steps"] > 0
    assert 1.2 + CLEAR < z_max < 1.2 + CLEAR + 3 * SETTLE and gap > BOUND


def test_no_climb_over_a_wall_above_the_ceiling(cache):
    # the same wall 3 m high needs a cruise height of 3.55 m: above a 3.5 m ceiling, no climb;
    # with the default ceiling (6 m) it climbs
    outcome, z_max, _, stats = fly(corridor(3.0), {"climb_ceiling": 3.5}, cache, t_max=8.0)
    assert outcome == "timeout" and stats["climbs"] == 0 and z_max < 1.5
    outcome, z_max, _, stats = fly(corridor(3.0), {}, cache)
    assert outcome == "goal" and stats["climbs"] == 1 and z_max > 3.0 + CLEAR


def test_plan_height_is_the_highest_top_near_the_line():
    # the low wall (top 1.2 m) and, 1 m beside the line, a box whose top is 1.6 m: within the
    # body's radius + margin + SETTLE of the line it counts, 2 m away it does not
    box = lambda y: {"shape": "box", "pos": [3.0, y, 0.8], "quat": [0.0, 0.0, 0.0, 1.0], "size": [0.3, 0.3, 0.8]}  # noqa: E731
    c = Climb(corridor(1.2, [box(0.8)]), 0.15, 6.0, 1.0, 2.5)
    plan = c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 1.0, (5.0, 0.0, 1.0))
    assert plan.z_c == pytest.approx(1.6 + CLEAR + SETTLE) and plan.stop == (-0.9, 0.0) and plan.phase == "rise"
    c = Climb(corridor(1.2, [box(2.0)]), 0.15, 6.0, 1.0, 2.5)
    assert c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 1.0, (5.0, 0.0, 1.0)).z_c == pytest.approx(1.2 + CLEAR + SETTLE)
    # the braking run: at 1 m/s along the wall it stops 1 / k_v = 0.4 m on
    plan = c.plan((-0.9, 0.0), (-0.9, 0.1), (0.0, 1.0), 1.0, (5.0, 0.0, 1.0))
    assert plan.stop == pytest.approx((-0.9, 0.5))
    # never below the body or the waypoint
    assert c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 2.5, (5.0, 0.0, 1.0)).z_c == 2.5
    assert c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 1.0, (5.0, 0.0, 2.5)).z_c == 2.5


def test_never_descends_onto_an_obstacle():
    # a pole 2 m long (0.2 m thick) leaning 45 degrees over the waypoint (5, 0, 0.85): the waypoint
    # itself is clear (0.25 m round the body) but the column above it runs into the pole's top
    pole = {
        "shape": "box",
        "pos": [6.0, 0.0, 0.78],
        "quat": quat_from_euler(0.0, -math.pi / 4, 0.0),
        "size": [0.1, 0.1, 1.0],
    }
    room = corridor(1.2, [pole])
    assert room_distance(room, [[5.0, 0.0, 0.85]])[0] - BOUND == pytest.approx(0.658 - 0.1 - BOUND, abs=0.01)
    assert room_distance(room, [[5.0, 0.0, 1.5]])[0] < BOUND
    c = Climb(room, 0.15, 6.0, 1.0, 2.5)
    assert c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 1.0, (5.0, 0.0, 0.85)) is None
    # 1.5 m farther from it the column is clear, and the pole 1.5 m beyond the line's end less
    # its bounding radius (1.01 m): a plan over the wall alone
    plan = c.plan((-0.9, 0.0), (-0.9, 0.0), (0.0, 0.0), 1.0, (3.5, 0.0, 0.85))
    assert plan.z_c == pytest.approx(1.2 + CLEAR + SETTLE)
    # braking into the wall's face (0.5 m from it at 1.5 m/s: it stops 0.6 m on) is refused
    assert c.plan((-1.0, 0.0), (-0.9, 0.0), (1.5, 0.0), 1.0, (3.5, 0.0, 0.85)) is None


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-7.0, 11.0),
    y=st.floats(-4.0, 4.0),
    z=st.floats(0.5, 2.0),
    wx=st.floats(-7.0, 11.0),
    wy=st.floats(-4.0, 4.0),
    wz=st.floats(0.5, 2.0),
    yaw=st.floats(-3.0, 3.0),
    tilt=st.floats(-1.0, 1.0),
)
def test_every_plan_leaves_its_margin_along_its_whole_path(x, y, z, wx, wy, wz, yaw, tilt):
    # a room with a tilted box and a sphere beside the low wall: whatever the body and the
    # waypoint, a plan's path (rise column, line at z_c, descent column) stays clear
    objects = [
        {"shape": "box", "pos": [3.0, 1.0, 0.7], "quat": quat_from_euler(tilt, 0.3, yaw), "size": [0.5, 0.2, 0.4]},
        {"shape": "sphere", "pos": [-3.0, -1.0, 0.9], "quat": [0.0, 0.0, 0.0, 1.0], "size": [0.9]},
    ]
    room = corridor(1.2, objects)
    plan = Climb(room, 0.15, 6.0, 1.0, 2.5).plan((x, y), (x, y), (0.0, 0.0), z, (wx, wy, wz))
    if plan is None:
        return
    t = np.linspace(0.0, 1.0, 400)[:, None]
    rise = np.column_stack([np.full(100, x), np.full(100, y), np.linspace(z, plan.z_c, 100)])
    line = np.column_stack([x + t * (wx - x), y + t * (wy - y), np.full(400, plan.z_c - SETTLE)])
    down = np.column_stack([np.full(100, wx), np.full(100, wy), np.linspace(wz, plan.z_c, 100)])
    # the samples 0.1 m apart may miss up to half that of the margin
    assert (room_distance(room, np.concatenate([rise, line])) - BOUND).min() > 0.15 - 0.05
    assert (room_distance(room, down) - BOUND).min() > 0.15 + DESCEND - 0.05
    assert plan.z_c >= max(z, wz)


def test_commands_of_each_phase():
    c = Climb(corridor(1.2), 0.15, 6.0, 1.0, 2.5)
    plan = ClimbPlan((-0.9, 0.5), 1.8, (5.0, 0.0, 1.0))
    # rise: the point the body would stop at (p + v / k_v) moved to the braking point (1 /s, at
    # most 0.5 m/s); climbing at 1.5 /s, capped at the speed
    assert c.command(plan, -0.9, 0.0, 1.0, 0.0, 0.0) == pytest.approx((0.0, 0.5, 1.0))
    assert c.command(plan, -0.9, 0.3, 1.6, 0.0, 0.25) == pytest.approx((0.0, 0.1, 0.3)) and plan.phase == "rise"
    assert c.command(plan, -0.9, 0.0, 1.0, 0.0, 1.25) == pytest.approx((0.0, 0.0, 1.0))  # stops there: no command
    # within SETTLE of the point and of z_c: the line, toward the waypoint at the pilot's 1.5 m/s
    vx, vy, vz = c.command(plan, -0.9, 0.45, 1.75, 0.0, 0.0)
    assert plan.phase == "line" and math.hypot(vx, vy) == pytest.approx(1.5) and vz == pytest.approx(0.075)
    assert vy / vx == pytest.approx(-0.45 / 5.9)
    # within DESCEND of the waypoint: down to its height, at most the speed
    assert c.command(plan, 4.9, 0.0, 1.8, 1.0, 0.0) == pytest.approx((0.1, 0.0, -1.0)) and plan.phase == "descend"
    assert c.command(plan, 5.0, 0.0, 1.2, 0.0, 0.0) == pytest.approx((0.0, 0.0, -0.3))
    assert c.command(plan, 5.0, 0.0, 1.05, 0.0, 0.0) is None  # within SETTLE of its height: over


def test_room_distance_and_tops_hand_computed():
    room = corridor(
        1.2,
        [
            {
                "shape": "cylinder",
                "pos": [-4.0, 2.0, 0.5],
                "quat": quat_from_euler(math.pi / 2, 0.0, 0.0),
                "size": [0.5, 1.0],
            }
        ],
    )
    d = room_distance(room, [[-0.7, 0.0, 1.0], [0.5, 0.0, 2.2], [-4.0, 2.0, 1.5], [-6.0, 0.0, 0.3]])
    # 0.7 m from the wall's face (the floor 1 m below); 1 m above its top; the lying cylinder (axis along y, radius 0.5,
    # centre 0.5 m up) 0.5 m below; the floor 0.3 m below
    assert d == pytest.approx([0.7, 1.0, 0.5, 0.3])
    assert object_top(room.objects[0]) == pytest.approx(1.0)
    box = {
        "shape": "box",
        "pos": [0.0, 0.0, 1.0],
        "quat": quat_from_euler(0.0, math.pi / 4, 0.0),
        "size": [0.5, 0.5, 0.5],
    }
    assert object_top(box) == pytest.approx(1.0 + 0.5 * math.sqrt(2.0))


@pytest.mark.parametrize(
    "kw, msg",
    [
        ({"climb_after": -1.0}, "climb_after must be a finite number >= 0.0, got -1.0"),
        ({"climb_after": "soon"}, "climb_after must be a number, got 'soon'"),
        ({"climb_margin": 0.0}, "climb_margin must be a finite number > 0.0, got 0.0"),
        ({"climb_ceiling": float("nan")}, "climb_ceiling must be a finite number > 0.0, got nan"),
        ({"climb_speed": float("inf")}, "climb_speed must be a finite number > 0.0, got inf"),
    ],
)
def test_bad_climb_options_named(kw, msg):
    with pytest.raises(ValueError, match=msg):
        QuadrotorHJGuardian(**kw)
    with pytest.raises(ValueError, match=msg):
        make_guardian("hj", env_id="QuadrotorRoomParallel-v0", quadrotor=kw)
