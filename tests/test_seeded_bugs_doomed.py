"""Doomed starts whose verdict depends on continuing the search from each branch's end (issue 49):
a search that restarted every segment from the branch's first state (``paths[alive, 0, :]``, so
only constant controls from the start) passed every other test.  Hand-built cases where the two
disagree, both ways, for the Dubins4D car among circles and the maze car, each with a witness
(the sequence that escapes, or why the constant controls are fooled)."""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.dubins4d.doomed import DUBINS4D_METHOD, DUBINS4D_SEGMENTS, dubins4d_escapes
from rmm_envs.systems.dubins4d.dynamics import Dubins4D
from rmm_envs.systems.maze.doomed import MAZE_SEGMENTS, maze_escapes
from rmm_envs.systems.maze.dynamics import Dubins3D
from rmm_envs.systems.maze.mazes import Maze

CAR = Dubins4D()  # turn rate within +-0.25 rad/s, acceleration within +-0.5 m/s^2
FAR = (50.0, 50.0, 0.5)
OPTIONS = [(w, a) for w in (-0.25, 0.0, 0.25) for a in (-0.5, 0.5)]


def _path(state, controls: list[tuple[float, float, float]], dt: float = 0.01) -> np.ndarray:
    """The car's positions ``(T, 2)`` under piecewise-constant ``(turn, accel, seconds)`` controls."""
    state = np.asarray(state, float).reshape(1, 4)
    out = [state[0, :2]]
    for w, a, seconds in controls:
        times = np.linspace(0.0, seconds, int(round(seconds / dt)) + 1)
        p = CAR.states_at(state, np.array([[w, a]]), times, compiled=False)[0]
        out.append(p[1:, :2])
        state = p[-1:].copy()
    return np.concatenate([np.atleast_2d(o) for o in out])


def _clear(path: np.ndarray, obstacles) -> bool:
    return all(np.hypot(*(path - (x, y)).T).min() > r for x, y, r in obstacles)


def test_a_wall_reached_only_after_the_first_segments_is_doomed():
    """At 2 m/s the car needs 4 s and 4 m to stop; a wall (a circle of radius 50) 3.5 m ahead.
    Full braking for the last segment's 2.5 s alone covers 2 * 2.5 - 0.25 * 2.5^2 = 3.44 m, so
    any constant control from the start looks clear for 2.5 s; continued from the branches' ends
    over the whole 4 s, every sequence touches the wall: doomed."""
    assert sum(DUBINS4D_SEGMENTS) == 4.0
    wall = [(53.5, 0.0, 50.0)]
    assert not dubins4d_escapes(CAR, (0.0, 0.0, 0.0, 2.0), wall, FAR)
    braking = _path((0.0, 0.0, 0.0, 2.0), [(0.0, -0.5, 2.5)])
    assert _clear(braking, wall)  # what a search from the start alone would take for an escape
    assert not _clear(_path((0.0, 0.0, 0.0, 2.0), [(0.0, -0.5, 4.0)]), wall)
    # 4.5 m ahead, braking stops short of it
    assert dubins4d_escapes(CAR, (0.0, 0.0, 0.0, 2.0), [(54.5, 0.0, 50.0)], FAR)


def test_an_escape_that_changes_control_between_segments_is_found():
    """Six small posts, one where each constant extreme control puts the car after 2 s (from 2 m/s):
    every constant control collides, but turning left for the first 0.5 s and braking straight
    after passes between them: avoidable."""
    start = (0.0, 0.0, 0.0, 2.0)
    posts = [(3.0, 0.0, 0.15), (4.0, 0.0, 0.15), (2.9, 0.65, 0.15), (2.9, -0.65, 0.15), (3.84, 0.98, 0.15),
             (3.84, -0.98, 0.15)]  # fmt: skip
    for w, a in OPTIONS:
        assert not _clear(_path(start, [(w, a, 2.5)]), posts), (w, a)
    escape = _path(start, [(0.25, -0.5, 0.5), (0.0, -0.5, 1.0), (0.0, -0.5, 2.5)])
    assert _clear(escape, posts)
    assert dubins4d_escapes(CAR, start, posts, FAR)


# ---------------------------------------------------------------- the maze car

MAZE_CAR = Dubins3D()  # 10 px/s, turning radius 50 px
NOWHERE = (-1e6, -1e6, 1.0)
POSE = np.array([200.0, 200.0, 0.0])  # the middle of a 400 px room, heading +x


def _room(*walls) -> Maze:
    sides = [(0, 0, 400, 0), (400, 0, 400, 400), (400, 400, 0, 400), (0, 400, 0, 0)]
    return Maze(np.array(sides + list(walls), float), width=400.0, height=400.0)


def _hits(maze: Maze, turns: list[tuple[float, float]], pose=POSE) -> bool:
    """Whether the maze car from ``pose`` under ``(turn rate, seconds)`` pieces touches a wall."""
    state = np.asarray(pose, float).reshape(1, 3)
    for u, seconds in turns:
        n = int(round(seconds / 0.1)) + 1
        path = MAZE_CAR.propagate(state, np.array([u]), seconds, n)
        if maze.paths_hit(path)[0]:
            return True
        state = path[:, -1]
    return False


def test_a_dead_end_beyond_the_first_segments_is_doomed():
    """A corridor 60 px wide (too narrow to turn round: the radius is 50 px) closed 110 px ahead:
    driving straight is clear for the first 8 s (80 px), which a search from the start alone
    takes for an escape; every sequence over the whole 14 s reaches a wall: doomed."""
    assert sum(MAZE_SEGMENTS) == 14.0
    corridor = _room((100, 170, 300, 170), (100, 230, 300, 230), (310, 170, 310, 230), (100, 170, 100, 230))
    u = MAZE_CAR.u_max
    assert not _hits(corridor, [(0.0, 8.0)])
    assert _hits(corridor, [(0.0, 14.0)]) and _hits(corridor, [(u, 2 * math.pi / u)])
    assert not maze_escapes(MAZE_CAR, corridor, POSE, NOWHERE)
    # open further on: 130 px of corridor and more, the search reaches its end clear
    longer = _room((100, 170, 390, 170), (100, 230, 390, 230), (100, 170, 100, 230))
    assert maze_escapes(MAZE_CAR, longer, POSE, NOWHERE)


def test_a_loop_found_only_from_the_end_of_a_piece_makes_the_start_avoidable():
    """Three posts in an open room: one on each of the start's two loops, 60 px of arc on, and one
    60 px straight ahead.  Every constant turn from the start hits a post within 8 s, and neither
    loop from the start is clear; but after 2 s straight, a full left loop touches nothing, and the
    car can drive it for ever: avoidable."""
    a = 1.2  # 60 px of arc on a 50 px radius
    x, y = 200 + 50 * math.sin(a), 50 * (1 - math.cos(a))
    room = _room((x, 200 + y, x + 0.5, 200 + y), (x, 200 - y, x + 0.5, 200 - y), (260, 200, 260.5, 200))
    u = MAZE_CAR.u_max
    loop = 2 * math.pi / u
    for turn in (-u, 0.0, u):
        assert _hits(room, [(turn, 8.0)]), turn
    assert _hits(room, [(u, loop)]) and _hits(room, [(-u, loop)])
    assert not _hits(room, [(0.0, 2.0), (u, loop)]) and not _hits(room, [(0.0, 2.0), (-u, loop)])
    assert maze_escapes(MAZE_CAR, room, POSE, NOWHERE)


# ---------------------------------------------------------------- a map of your own (pymunk's contacts)


def _map_start(wall_x: float, goal=(-8.0, -8.0, 0.5)):
    """The doomed test of a map env whose only obstacle is a straight wall (a segment 0.4 m thick)
    whose near face is ``wall_x`` m ahead of the car at 2 m/s."""
    import gymnasium as gym

    import rmm_envs  # noqa: F401  (registers the envs)
    from rmm_envs.starts import assess_start

    wall = {"segment": [[wall_x + 0.2, -20.0], [wall_x + 0.2, 20.0], 0.4]}
    env = gym.make("Dubins4DMapGuarded-v0", map=[wall, {"start": [[-10.0, -10.0], [10.0, 10.0]]}])
    env.reset(seed=0, options={"state": [0.0, 0.0, 0.0, 2.0], "goal": list(goal)})
    return assess_start(env)


def test_a_maps_wall_reached_only_after_the_first_segments_is_doomed():
    """The same search with the map's exact contact test: a flat wall 3.5 m ahead is doomed (the
    first 2.5 s of braking stop short of it), 4.5 m ahead avoidable, and a goal before the wall
    saves the start."""
    doomed = _map_start(3.5)
    assert doomed.doomed is True and doomed.method == DUBINS4D_METHOD
    assert _map_start(4.5).doomed is False
    assert _map_start(3.5, goal=(1.0, 0.0, 0.3)).doomed is False
    assert _map_start(1.0).doomed is True and _map_start(1.0, goal=(0.5, 0.0, 0.2)).doomed is False
