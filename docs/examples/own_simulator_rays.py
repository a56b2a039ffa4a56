"""Your own simulator with rays: a point robot among three circles, labelled at array speed.

The simulator ``PointRays`` in plain numpy (a double integrator in a 6 m x 6 m room with three
circular obstacles, eight range rays as its observation), knowing nothing of rmm_envs: the
snapshot protocol plus ``step_batch``, the same step on many states at once, so a risk label's
tree is stepped at array speed.  ``python -m benchmarks.perf_snapshot_batch`` times its labels
both ways (the tutorial's ``own_simulator_wall.py`` shows the rest of the path: a driver, a safe
default and ``guarded``).

State ``(x, y, vx, vy)`` (m, m/s); action ``(ax, ay)`` in ``[-1, 1]^2`` m/s^2 held for each 0.1 s
step; failure: inside an obstacle or outside the room.  Observation: the eight rays' ranges (up
to 3 m; headings 0, 45, ..., 315 degrees) and the velocity.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

ROOM = 3.0  # the room is [-3, 3]^2 m
CIRCLES = np.array([[1.0, 0.5, 0.6], [-1.2, -0.8, 0.7], [0.2, -1.8, 0.5]])  # x, y, radius (m)
RAY_RANGE = 3.0
ANGLES = np.arange(8) * (np.pi / 4)
VMAX = 2.0


def _collides(x, y):
    """(N,) whether each point is inside an obstacle or outside the room."""
    out = (np.abs(x) >= ROOM) | (np.abs(y) >= ROOM)
    for cx, cy, r in CIRCLES:
        out |= (x - cx) ** 2 + (y - cy) ** 2 <= r * r
    return out


def _step_arrays(x, y, vx, vy, ax, ay, dt):
    """One step of the double integrator, velocity clipped to VMAX per axis (the one formula of
    ``step`` and ``step_batch``, so both give the same bits)."""
    vx2 = np.clip(vx + dt * ax, -VMAX, VMAX)
    vy2 = np.clip(vy + dt * ay, -VMAX, VMAX)
    return x + 0.5 * dt * (vx + vx2), y + 0.5 * dt * (vy + vy2), vx2, vy2


def ray_ranges(x: float, y: float) -> np.ndarray:
    """The eight rays' ranges from (x, y): the nearest circle or wall along each, at most RAY_RANGE."""
    c, s = np.cos(ANGLES), np.sin(ANGLES)
    best = np.full(8, RAY_RANGE)
    for cx, cy, r in CIRCLES:  # |p + t u - c|^2 = r^2: the smaller root ahead
        fx, fy = x - cx, y - cy
        b = fx * c + fy * s
        disc = b * b - (fx * fx + fy * fy - r * r)
        t = -b - np.sqrt(np.maximum(disc, 0.0))
        best = np.where((disc >= 0) & (t >= 0), np.minimum(best, t), best)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (ROOM - x) / c, np.where(c < 0, (-ROOM - x) / c, np.inf))
        ty = np.where(s > 0, (ROOM - y) / s, np.where(s < 0, (-ROOM - y) / s, np.inf))
    return np.minimum(best, np.minimum(tx, ty))


class PointRays:
    """A point robot among three circles; see the module docstring."""

    dt = 0.1
    action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
    observation_space = gym.spaces.Box(-np.inf, np.inf, (10,), np.float32)
    default_horizon = 1.0  # s: each random control of a risk label's tree is held for 10 steps

    def __init__(self):
        self.state = np.array([-2.5, 2.0, 0.0, 0.0])

    # -- the snapshot protocol ----------------------------------------------------------------
    def get_state(self):
        return self.state.copy()

    def set_state(self, state):
        self.state = np.array(state, dtype=float)

    def step(self, action):  # True when this step hits an obstacle or a wall
        a = np.asarray(action, dtype=float)
        x, y, vx, vy = _step_arrays(*(self.state[i : i + 1] for i in range(4)), a[:1], a[1:2], self.dt)
        self.state = np.concatenate([x, y, vx, vy])
        return bool(_collides(x, y)[0])

    def state_failed(self, states):
        states = np.asarray(states, dtype=float)
        return _collides(states[:, 0], states[:, 1])

    # -- optional hooks --------------------------------------------------------------------------
    def step_batch(self, states, actions):
        a = np.asarray(actions, dtype=float)
        x, y, vx, vy = _step_arrays(states[:, 0], states[:, 1], states[:, 2], states[:, 3], a[:, 0], a[:, 1], self.dt)
        return np.column_stack([x, y, vx, vy]), _collides(x, y)

    def observe(self, state):
        return np.concatenate([ray_ranges(state[0], state[1]), state[2:4]]).astype(np.float32)

    def sample_states(self, rng, n):
        return np.column_stack([rng.uniform(-ROOM, ROOM, (n, 2)), rng.uniform(-VMAX, VMAX, (n, 2))])

    def initial_state(self, rng):
        return np.array([-2.5, rng.uniform(1.5, 2.5), 0.0, 0.0])
