"""A quadrotor in procedurally generated rooms: ``QuadrotorRoom-v0`` (PyBullet).

The paper's high-dimensional system (Fig. 3, Table II; docs/original-code.md, item 26).

## Description

A rigid quadrotor body (:file:`rmm_envs/assets/quadrotor.urdf`: 0.5 kg, inertia
``diag(0.0023, 0.0023, 0.004)`` kg m^2, a collision cylinder of radius 0.3 m and length 0.1 m)
flies in a room from :func:`rmm_envs.worlds.rooms.generate_room`, simulated by PyBullet
(``DIRECT``, no display) at 240 Hz with gravity 9.81 m/s^2 and PyBullet's default linear and
angular damping (0.04).  Every physics step applies the action's body-frame thrust along
the body z axis and body-frame moments (``applyExternalForce`` / ``applyExternalTorque`` in
``LINK_FRAME``).

## Action space

``Box([0, -2, -2, -1], [8, 2, 2, 1], (4,), float32)``: thrust ``F`` (N) and moments
``(Mx, My, Mz)`` (N m).  Hover thrust is ``m g = 4.905`` N.  Values outside the bounds are
clipped; NaN/inf or a wrong shape raise ``ValueError``.

## Observation space

``Box(16,)`` float32:

| index | observation | range |
|---|---|---|
| 0-5 | ray ranges along body +x, +y, -x, -y, +z, -z (m, 100 when nothing is hit) | [0, 100] |
| 6-9 | orientation quaternion (x, y, z, w) | [-1, 1] |
| 10-12 | linear velocity, world frame (m/s) | R |
| 13-15 | angular velocity, world frame (rad/s) | R |

Rays start at the body's origin and use ``rayTestBatch`` (they do not hit the body itself).

## State

13 numbers: position, quaternion (x, y, z, w), linear and angular velocity in the **world**
frame (PyBullet's convention, also the original's).  ``info["state"]`` carries it (privileged).

## Dynamics and episode end

Each ``step`` holds the action for ``control_dt`` (default 1/24 s = 10 physics steps).
``terminated`` on any contact of the body with anything (walls, objects, the floor), checked
after every physics step; reward ``-1`` then, else 0.  ``truncated`` after
``max_episode_time`` (20 s) of simulated time.

## Starting state

A room from the seed; a position above a random footprint cell at height ``U(0.3, 3)`` m,
a random yaw with roll and pitch ``U(-0.3, 0.3)`` rad, linear velocity ``U(-1, 1)`` m/s and
angular velocity ``U(-0.5, 0.5)`` rad/s per axis, redrawn while in contact.
``reset(seed, options={"state": [13 numbers], "room": Room or dict of generate_room
arguments})`` sets either.  With a given state and a generated room (from the seed, or from
the given ``generate_room`` arguments) the room is redrawn until the state is clear of it, as
generation keeps states clear; a state in contact with a given ``Room`` (or with every one of
100 drawn rooms), a non-unit quaternion, or a bad room option raises ``ValueError``.  Without
options the draws are exactly those of generation.

## Arguments

``gym.make("QuadrotorRoom-v0", control_dt=1/24, max_episode_time=20.0, linear_damping=0.04,
angular_damping=0.04, render_mode=None)``

## Rendering

``render_mode="rgb_array"``: a 320 x 240 frame from PyBullet's software renderer (TinyRenderer,
no display needed), from behind and above the body.
"""

from __future__ import annotations

import math
from dataclasses import replace

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from rmm_envs.risk.protocol import SceneBase
from rmm_envs.systems.quadrotor import QUADROTOR, Quadrotor
from rmm_envs.worlds.room_collision import RoomCollision
from rmm_envs.worlds.rooms import Room, build_room, generate_room

__all__ = ["QuadrotorRoomEnv", "QuadrotorScene"]

RAY_RANGE = 100.0
_RAY_DIRS = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


def _urdf_path() -> str:
    from importlib import resources

    return str(resources.files("rmm_envs") / "assets" / "quadrotor.urdf")


class QuadrotorScene(SceneBase):
    """The quadrotor in one room: the :class:`rmm_envs.risk.System` for fast labelling.

    Propagation is the batched numpy integrator (:class:`rmm_envs.systems.Quadrotor`, which
    reproduces PyBullet's), failure is the analytic room collision at the path's states (as
    the original checked its 8 path states), and observations come from the env's PyBullet
    rays.  PyBullet stays the environment's truth; the tests compare the two.
    """

    state_dim, control_dim, obs_dim = 13, 4, 16

    def __init__(self, env: "QuadrotorRoomEnv") -> None:
        self.env = env
        self.system = Quadrotor(env.params)
        self.collision = RoomCollision(env.room)

    def state_failed(self, states):
        return self.collision.states_failed(np.asarray(states, float))

    def path_failed(self, paths):
        paths = np.asarray(paths, float)
        return self.collision.states_failed(paths.reshape(-1, 13)).reshape(paths.shape[:2]).any(axis=1)

    def observe(self, states, *_):
        return self.env.observe_states(states)


class QuadrotorRoomEnv(gym.Env):
    """See the module docstring for the full specification."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 24}

    def __init__(self, control_dt: float = 1.0 / 24.0, max_episode_time: float = 20.0,
                 linear_damping: float = QUADROTOR.linear_damping, angular_damping: float = QUADROTOR.angular_damping,
                 render_mode: str | None = None):
        try:
            import pybullet as p
        except ImportError as e:
            raise gym.error.DependencyNotInstalled(
                "QuadrotorRoom-v0 needs PyBullet: pip install 'rmm-envs[quadrotor]' (pybullet==3.2.7)"
            ) from e

        n_sub = control_dt / QUADROTOR.dt
        if not (control_dt > 0 and abs(n_sub - round(n_sub)) < 1e-9 and round(n_sub) >= 1):
            raise ValueError(f"control_dt must be a positive multiple of 1/240 s, got {control_dt!r}")
        if not (max_episode_time > 0 and math.isfinite(max_episode_time)):
            raise ValueError(f"max_episode_time must be a finite number of seconds > 0 (episodes need a time limit), got {max_episode_time!r}")
        if not (linear_damping >= 0 and angular_damping >= 0 and math.isfinite(linear_damping) and math.isfinite(angular_damping)):
            raise ValueError(f"damping must be finite and >= 0, got {linear_damping}, {angular_damping}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.p = p
        self.n_sub = int(round(n_sub))
        self.control_dt = float(control_dt)
        self.max_episode_time = float(max_episode_time)
        self.damping = (float(linear_damping), float(angular_damping))
        self.params = replace(QUADROTOR, linear_damping=self.damping[0], angular_damping=self.damping[1])
        self.render_mode = render_mode
        self.action_space = spaces.Box(np.array(self.params.control_low, np.float32), np.array(self.params.control_high, np.float32), dtype=np.float32)
        low = np.array([0] * 6 + [-1] * 4 + [-np.inf] * 6, np.float32)
        high = np.array([RAY_RANGE] * 6 + [1] * 4 + [np.inf] * 6, np.float32)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.client = p.connect(p.DIRECT)
        self.room: Room | None = None
        self.body = None
        self._t = 0.0
        self._done = False

    # ------------------------------------------------------------------ world
    def _build(self, room: Room) -> None:
        p, c = self.p, self.client
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0, 0, -self.params.gravity, physicsClientId=c)
        p.setTimeStep(self.params.dt, physicsClientId=c)
        build_room(c, room)
        self.body = p.loadURDF(_urdf_path(), [0, 0, 1], physicsClientId=c, flags=p.URDF_USE_INERTIA_FROM_FILE)
        p.changeDynamics(self.body, -1, linearDamping=self.damping[0], angularDamping=self.damping[1], physicsClientId=c)
        self.room = room

    def set_state(self, state) -> None:
        s = np.asarray(state, float)
        self.p.resetBasePositionAndOrientation(self.body, s[0:3].tolist(), s[3:7].tolist(), physicsClientId=self.client)
        self.p.resetBaseVelocity(self.body, s[7:10].tolist(), s[10:13].tolist(), physicsClientId=self.client)

    def get_state(self) -> np.ndarray:
        if self.body is None:
            raise RuntimeError("call reset() first")
        pos, quat = self.p.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        v, w = self.p.getBaseVelocity(self.body, physicsClientId=self.client)
        return np.array([*pos, *quat, *v, *w])

    def in_contact(self) -> bool:
        self.p.performCollisionDetection(physicsClientId=self.client)
        return len(self.p.getContactPoints(bodyA=self.body, physicsClientId=self.client)) > 0

    def _random_state(self, rng) -> np.ndarray:
        cells = np.argwhere(self.room.footprint)
        for _ in range(1000):
            ij = cells[rng.integers(len(cells))]
            xy = self.room.origin + (ij + rng.uniform(0, 1, 2)) * self.room.cell
            z = rng.uniform(0.3, 3.0)
            r, pt = rng.uniform(-0.3, 0.3, 2)
            q = self.p.getQuaternionFromEuler([r, pt, rng.uniform(-np.pi, np.pi)])
            s = np.array([xy[0], xy[1], z, *q, *rng.uniform(-1, 1, 3), *rng.uniform(-0.5, 0.5, 3)])
            self.set_state(s)
            if not self.in_contact():
                return s
        raise RuntimeError("could not place the quadrotor clear of obstacles in 1000 draws")

    _MAX_ROOM_DRAWS = 100

    def _draw_room(self, spec) -> Room:
        if spec is None:
            return generate_room(self.np_random)
        if isinstance(spec, Room):
            return spec
        try:
            return generate_room(self.np_random, **spec)
        except TypeError as e:
            raise ValueError(f"option 'room': {e}") from None

    # ------------------------------------------------------------------ API
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"state", "room"}
        if unknown:
            raise ValueError(f"unknown reset options {sorted(unknown)}; expected any of 'state', 'room'")
        s = None
        if "state" in options:
            s = np.asarray(options["state"], float).reshape(-1)
            if s.shape != (13,) or not np.all(np.isfinite(s)):
                raise ValueError(f"option 'state' must be 13 finite numbers (position, quaternion xyzw, velocity, angular velocity), got shape {s.shape}")
            if abs(np.linalg.norm(s[3:7]) - 1) > 1e-6:
                raise ValueError(f"option 'state': the quaternion {s[3:7].tolist()} is not a unit quaternion")
        spec = options.get("room")
        if spec is not None and not isinstance(spec, (Room, dict)):
            raise ValueError(f"option 'room' must be a Room or a dict of generate_room arguments, got {type(spec).__name__}")
        if s is None:
            self._build(self._draw_room(spec))
            self._random_state(self.np_random)
        elif isinstance(spec, Room):
            self._build(spec)
            self.set_state(s)
            if self.in_contact():
                raise ValueError(f"option 'state': the body at {s[:3].tolist()} is in contact with option 'room'")
        else:
            # a generated room (from the seed, or from the given generate_room arguments) is
            # redrawn until the given state is clear of it, as generation keeps states clear
            for _ in range(self._MAX_ROOM_DRAWS):
                self._build(self._draw_room(spec))
                self.set_state(s)
                if not self.in_contact():
                    break
            else:
                raise ValueError(f"option 'state': the body at {s[:3].tolist()} is in contact with each of "
                                 f"{self._MAX_ROOM_DRAWS} rooms drawn from the seed; give 'room' too or move the state")
        self._t = 0.0
        self._done = False
        return self._obs(), {"state": self.get_state(), "sim_time": 0.0}

    def rays(self) -> np.ndarray:
        p = self.p
        res = p.rayTestBatch([[0, 0, 0]] * 6, (RAY_RANGE * _RAY_DIRS).tolist(), parentObjectUniqueId=self.body,
                             parentLinkIndex=-1, physicsClientId=self.client)
        return np.array([RAY_RANGE * r[2] if r[0] >= 0 else RAY_RANGE for r in res])

    def _obs(self) -> np.ndarray:
        s = self.get_state()
        return np.concatenate([self.rays(), s[3:13]]).astype(np.float32)

    def step(self, action):
        if self.body is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("the episode has ended; call reset() before stepping again")
        a = np.asarray(action, dtype=float)
        if a.shape != (4,):
            raise ValueError(f"action must have shape (4,) in {self.action_space}, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite (space {self.action_space}), got {a.tolist()}")
        a = np.clip(a, self.action_space.low, self.action_space.high)
        p, c, b = self.p, self.client, self.body
        force, torque = [0.0, 0.0, float(a[0])], [float(a[1]), float(a[2]), float(a[3])]
        hit = False
        for _ in range(self.n_sub):
            p.applyExternalForce(b, -1, force, [0, 0, 0], p.LINK_FRAME, physicsClientId=c)
            p.applyExternalTorque(b, -1, torque, p.LINK_FRAME, physicsClientId=c)
            p.stepSimulation(physicsClientId=c)
            self._t += self.params.dt
            if p.getContactPoints(bodyA=b, physicsClientId=c):
                hit = True
                break
        truncated = not hit and self._t >= self.max_episode_time - 1e-9
        info = {"state": self.get_state(), "sim_time": self._t}
        if hit or truncated:
            self._done = True
            info["outcome"] = "collision" if hit else "timeout"
        return self._obs(), (-1.0 if hit else 0.0), hit, truncated, info

    def privileged(self) -> dict:
        return {"state": self.get_state(), "room": self.room}

    # ------------------------------------------------------------------ dataset hooks
    def risk_system(self) -> QuadrotorScene:
        if self.room is None:
            raise RuntimeError("call reset() first")
        if getattr(self, "_scene", None) is None or self._scene.collision.room is not self.room:
            self._scene = QuadrotorScene(self)
        return self._scene

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """States as the original's datagen drew them: position uniform over the walls' box
        expanded by 15% per side (z from below the floor up), a uniformly random orientation,
        linear velocity uniform in [-10, 10]^3 m/s and angular velocity in [-4 pi, 4 pi]^3 rad/s;
        states in contact (analytically) are rejected."""
        lo, hi = self.room.bounds()
        span = hi - lo
        lo, hi = lo - 0.15 * span, hi + 0.15 * span
        col = self.risk_system().collision
        out = np.empty((0, 13))
        while out.shape[0] < n:
            k = max(2 * (n - out.shape[0]), 16)
            q = rng.normal(size=(k, 4))
            q /= np.linalg.norm(q, axis=1, keepdims=True)
            cand = np.column_stack([rng.uniform(lo, hi, (k, 3)), q, rng.uniform(-10, 10, (k, 3)),
                                    rng.uniform(-4 * np.pi, 4 * np.pi, (k, 3))])
            out = np.vstack([out, cand[~col.states_failed(cand)]])
        return out[:n]

    def observe_states(self, states, rng=None) -> np.ndarray:
        """The 16-dim observation of arbitrary states (PyBullet rays; the env's state is restored)."""
        keep = self.get_state()
        obs = np.empty((len(states), 16), dtype=np.float32)
        for i, st in enumerate(np.asarray(states, float)):
            self.set_state(st)
            obs[i, :6] = self.rays()
            obs[i, 6:] = st[3:13]
        self.set_state(keep)
        return obs

    @property
    def true_state(self) -> np.ndarray:
        return self.get_state()

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array'")
            return None
        p = self.p
        s = self.get_state()
        view = p.computeViewMatrixFromYawPitchRoll(s[:3].tolist(), 4.0, 30.0, -35.0, 0.0, 2, physicsClientId=self.client)
        proj = p.computeProjectionMatrixFOV(60.0, 320 / 240, 0.05, 100.0, physicsClientId=self.client)
        _, _, rgba, _, _ = p.getCameraImage(320, 240, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=self.client)
        return np.asarray(rgba, dtype=np.uint8).reshape(240, 320, 4)[..., :3]

    def close(self):
        if getattr(self, "client", None) is not None:
            try:
                self.p.disconnect(physicsClientId=self.client)
            except Exception:
                pass
            self.client = None
