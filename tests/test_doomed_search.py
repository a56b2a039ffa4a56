"""The doomed searches' goal test and sampling on hand-built cases: a goal disc reached first
saves a start, measured with the radius the docstrings give (Dubins4D: the disc itself, sampled
every 20 ms from each segment's start; the maze car: the disc widened by one sample's travel),
reached by any sequence (not only the first tried), and never behind a wall
(tests/test_doomed.py and tests/test_seeded_bugs_doomed.py test the walls)."""

from __future__ import annotations

import numpy as np
import pytest

from rmm_envs.starts import StartAssessment
from rmm_envs.systems.dubins4d.doomed import DUBINS4D_DT, DUBINS4D_SEGMENTS, dubins4d_escapes
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.maze.doomed import MAZE_DT, maze_escapes
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.mazes import Maze

CAR = Dubins4D()  # turn rate within +-0.25 rad/s, acceleration within +-0.5 m/s^2
START = (0.0, 0.0, 0.0, 2.0)
WALL = [(51.5, 0.0, 50.0)]  # 1.5 m ahead of a car at 2 m/s, which needs 4 m to stop: doomed


def _at(controls: list[tuple[float, float, float]]) -> np.ndarray:
    """The car's position from START after piecewise-constant ``(turn, accel, seconds)`` controls,
    each piece evaluated at its own end from its own start, as the search samples it."""
    state = np.array([START])
    for w, a, seconds in controls:
        times = np.linspace(0.0, seconds, int(round(seconds / DUBINS4D_DT)) + 1)
        state = CAR.states_at(state, np.array([[w, a]]), times, compiled=False)[:, -1]
    return state[0, :2]


def test_without_a_goal_the_wall_is_doomed():
    assert not dubins4d_escapes(CAR, START, WALL, (50.0, 50.0, 0.5))
    assert not dubins4d_escapes(CAR, START, [(53.0, 0.0, 50.0)], (50.0, 50.0, 0.5))


def test_a_goal_disc_counts_by_its_own_radius():
    """The start inside the goal disc (0.25 m from a disc of 0.3 m) is saved; 0.6 m from it, with the
    car driving away, it is not."""
    assert dubins4d_escapes(CAR, START, WALL, (-0.25, 0.0, 0.3))
    assert not dubins4d_escapes(CAR, START, WALL, (-0.6, 0.0, 0.3))


def test_a_goal_reached_only_by_a_later_sequence_is_found_at_its_sample():
    """A goal of 0.5 mm where full left turn and full throttle put the car after 0.48 s (a sample:
    every 20 ms from the segment's start): only that sequence reaches it, in its first segment."""
    assert DUBINS4D_DT == 0.02 and DUBINS4D_SEGMENTS[0] == 0.5
    x, y = _at([(0.25, 0.5, 0.48)])
    assert dubins4d_escapes(CAR, START, WALL, (x, y, 0.0005))


def test_the_second_segment_starts_where_the_first_ends():
    """A goal of 0.5 mm on the path that turns left for the first segment's 0.5 s, then right,
    braking all along, 0.5 s into the second segment (the wall 3 m ahead)."""
    x, y = _at([(0.25, -0.5, 0.5), (-0.25, -0.5, 0.5)])
    assert dubins4d_escapes(CAR, START, [(53.0, 0.0, 50.0)], (x, y, 0.0005))


# ---------------------------------------------------------------- the maze car

MAZE_CAR = Dubins3D()  # 10 px/s, turning radius 50 px: one sample (0.1 s) is 1 px
NOWHERE = (-1e6, -1e6, 1.0)
POSE = np.array([200.0, 200.0, 0.0])
#: a corridor 60 px wide, closed 110 px ahead of POSE: every sequence reaches a wall (doomed)
CORRIDOR = Maze(
    np.array(
        [
            (0, 0, 400, 0),
            (400, 0, 400, 400),
            (400, 400, 0, 400),
            (0, 400, 0, 0),
            (100, 170, 300, 170),
            (100, 230, 300, 230),
            (310, 170, 310, 230),
            (100, 170, 100, 230),
        ],
        float,
    ),  # fmt: skip
    width=400.0,
    height=400.0,
)


def test_a_maze_goal_counts_within_its_radius_and_one_samples_travel():
    """The goal disc widened by one sample's travel (1 px): the start 2.5 px from a disc of radius 2
    is within 3 px and saved; 5 px from it, driving away, it is not."""
    assert MAZE_CAR.speed * MAZE_DT == 1.0
    assert not maze_escapes(MAZE_CAR, CORRIDOR, POSE, NOWHERE)
    assert maze_escapes(MAZE_CAR, CORRIDOR, POSE, (197.5, 200.0, 2.0))
    assert not maze_escapes(MAZE_CAR, CORRIDOR, POSE, (195.0, 200.0, 2.0))


def test_a_maze_goal_on_the_left_turn_alone_is_reached():
    """15 px ahead the left turn is 2.3 px to the left (50 - sqrt(50^2 - 15^2)): a goal of radius 1
    there is within 2 px of the left turn's path only (the straight one passes 2.3 px off, the
    right turn 4.6 px)."""
    assert maze_escapes(MAZE_CAR, CORRIDOR, POSE, (215.0, 202.3, 1.0))


def test_a_maze_goal_behind_the_wall_does_not_count():
    """The goal 20 px beyond the corridor's end: driving straight reaches its disc only through the
    wall, after touching it: doomed."""
    assert not maze_escapes(MAZE_CAR, CORRIDOR, POSE, (330.0, 200.0, 5.0))


def test_a_maze_goal_reached_inside_the_piece_that_touches_the_wall_saves_the_start():
    """From x = 290 heading into the corridor's end (x = 310), a goal of radius 1 at x = 295 is
    reached 5 samples out, about 15 samples before the wall: the start is saved although the goal
    and the wall fall in one piece of the search (30 samples), which must not date the contact by
    its piece."""
    near_end = np.array([290.0, 200.0, 0.0])
    assert not maze_escapes(MAZE_CAR, CORRIDOR, near_end, NOWHERE)
    assert maze_escapes(MAZE_CAR, CORRIDOR, near_end, (295.0, 200.0, 1.0))


@pytest.mark.parametrize("chunk", [1, 7, 30, 200])
def test_a_contact_is_dated_by_its_segment_whatever_the_piece_size(chunk):
    """A straight path 1 px per sample from x = 280 meets the corridor's end wall (x = 310, its
    half-thickness h) on the segment ending at the first sample within h of it: the same index for
    every piece size; a path that never touches is dated ``T``."""
    from rmm_envs.systems.maze.doomed import _maze_hits

    xs = 280.0 + np.arange(60.0)
    path = np.stack([xs, np.full_like(xs, 200.0)], axis=1)[None]
    clear = path.copy()
    clear[..., 0] -= 100.0  # 180 .. 239 along the corridor's middle, far from every wall
    expected = int(np.flatnonzero(xs >= 310.0 - CORRIDOR.half)[0])
    got = _maze_hits(CORRIDOR, np.concatenate([path, clear]), chunk)
    assert got.tolist() == [expected, 60]


def test_a_moving_quadrotor_start_is_not_assessed():
    """At rest (every generated start) a quadrotor start is avoidable by hovering; one that moves
    (any of the velocities and rates, state[7:13], above 1e-9) is not assessed, with no method."""
    pytest.importorskip("pybullet")
    import gymnasium as gym

    import rmm_envs  # noqa: F401  (registers the envs)
    from rmm_envs.systems.quadrotor.doomed import QUADROTOR_METHOD, quadrotor_test

    env = gym.make("QuadrotorRoomParallel-v0", clock="fixed:1")
    env.reset(seed=0)
    assert quadrotor_test(env) == StartAssessment(False, QUADROTOR_METHOD)
    rest = [float(v) for v in env.unwrapped.true_state]
    for i, v in ((7, 0.5), (12, 2e-9), (10, -0.1)):
        moving = list(rest)
        moving[i] = v
        env.reset(seed=0, options={"state": moving})
        assert quadrotor_test(env) == StartAssessment(None, ""), i
