"""A quadrotor in procedurally generated rooms: ``QuadrotorRoom-v0`` (PyBullet).

The paper's high-dimensional system (Fig. 3, Table II; docs/original-code.md, item 26).

## Description

A rigid quadrotor body (:file:`rmm_envs/assets/quadrotor.urdf`: 0.5 kg, inertia
``diag(0.0023, 0.0023, 0.004)`` kg m^2, a collision cylinder of radius 0.3 m and length 0.1 m)
flies in a room from :func:`rmm_envs.systems.quadrotor.rooms.generate_room`, simulated by PyBullet
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
The space is an :class:`rmm_envs.autonomy.ObservationBox` whose layout names the fields
``"rays"`` (0-3, the horizontal body-frame rays, at angles ``0, pi/2, pi, 3 pi/2`` from the body
x axis), ``"rays_vertical"`` (4-5, up and down), ``"orientation"`` (6-9), ``"velocity"``
(10-12) and ``"angular_velocity"`` (13-15).

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

## Risk labelling

The env follows the :class:`rmm_envs.risk.LabelledEnv` protocol: ``risk_scene()`` is the room's
:class:`rmm_envs.scenes.QuadrotorScene` (the numpy propagator built from this env's parameters,
analytic collision); ``sample_states(rng, n)`` draws states as the original's dataset generator
did (position uniform over the walls' box expanded by 15% per side, z from below the floor up,
a uniformly random orientation, linear velocity in ``[-10, 10]^3`` m/s, angular velocity in
``[-4 pi, 4 pi]^3`` rad/s, rejecting states in contact); ``observe_states(states)`` computes the
observation of each state with PyBullet's rays (``rng`` is unused; the env's state is restored).

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

from rmm_envs.autonomy import ObservationBox, ObservationLayout
from rmm_envs.envs.base import (
    LabelledEnvBase,
    check_arguments,
    draw_until,
    finite,
    option_vector,
    rejection_sample,
    state_rows,
)
from rmm_envs.machine_independent import norm, norms
from rmm_envs.systems.quadrotor.body import QUADROTOR
from rmm_envs.systems.quadrotor.pybullet_body import push_body, urdf_path
from rmm_envs.systems.quadrotor.rooms import Room, build_room, generate_room
from rmm_envs.systems.quadrotor.rotations import unit_quaternion_rows
from rmm_envs.systems.quadrotor.scene import QuadrotorScene

__all__ = ["QuadrotorRoomEnv", "QuadrotorScene", "observation_layout"]

RAY_RANGE = 100.0
_RAY_DIRS = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)


def observation_layout() -> ObservationLayout:
    """The observation table's named slices (see the module docstring)."""
    return ObservationLayout.of(
        ("rays", 4),
        ("rays_vertical", 2),
        ("orientation", 4),
        ("velocity", 3),
        ("angular_velocity", 3),
        ray_angles=[0.0, math.pi / 2, math.pi, 3 * math.pi / 2],
    )


class QuadrotorRoomEnv(LabelledEnvBase):
    """See the module docstring for the full specification."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 24}
    reset_options: tuple[str, ...] = ("state", "room")

    def __init__(
        self,
        control_dt: float = 1.0 / 24.0,
        max_episode_time: float = 20.0,
        linear_damping: float = QUADROTOR.linear_damping,
        angular_damping: float = QUADROTOR.angular_damping,
        render_mode: str | None = None,
    ):
        try:
            import pybullet as p
        except ImportError as e:
            raise gym.error.DependencyNotInstalled(
                "QuadrotorRoom-v0 needs PyBullet: the quadrotor extra, pip install -e '.[quadrotor]' in a clone (pybullet==3.2.7)"
            ) from e

        n_sub = control_dt / QUADROTOR.dt if finite(control_dt) else math.nan
        check_arguments(
            [
                (
                    control_dt > 0 and abs(n_sub - round(n_sub)) < 1e-9 and round(n_sub) >= 1,
                    "control_dt",
                    control_dt,
                    "a positive multiple of 1/240 s",
                ),
                (
                    finite(max_episode_time) and max_episode_time > 0,
                    "max_episode_time",
                    max_episode_time,
                    "a finite number of seconds > 0 (episodes need a time limit)",
                ),
                (finite(linear_damping) and linear_damping >= 0, "linear_damping", linear_damping, "finite and >= 0"),
                (
                    finite(angular_damping) and angular_damping >= 0,
                    "angular_damping",
                    angular_damping,
                    "finite and >= 0",
                ),
                self.check_render_mode(render_mode),
            ]
        )
        self.p = p
        self.n_sub = int(round(n_sub))
        self.control_dt = float(control_dt)
        self.max_episode_time = float(max_episode_time)
        self.damping = (float(linear_damping), float(angular_damping))
        self.params = replace(QUADROTOR, linear_damping=self.damping[0], angular_damping=self.damping[1])
        self.render_mode = render_mode
        self.action_space = spaces.Box(
            np.array(self.params.control_low, np.float32),
            np.array(self.params.control_high, np.float32),
            dtype=np.float32,
        )
        low = np.array([0] * 6 + [-1] * 4 + [-np.inf] * 6, np.float32)
        high = np.array([RAY_RANGE] * 6 + [1] * 4 + [np.inf] * 6, np.float32)
        self.observation_space = ObservationBox(low, high, observation_layout())
        self.client = p.connect(p.DIRECT)
        self.room: Room | None = None
        self.scene: QuadrotorScene | None = None
        self.body = None
        self._t = 0.0

    # ------------------------------------------------------------------ world
    def _build(self, room: Room) -> None:
        p, c = self.p, self.client
        p.resetSimulation(physicsClientId=c)
        p.setGravity(0, 0, -self.params.gravity, physicsClientId=c)
        p.setTimeStep(self.params.dt, physicsClientId=c)
        build_room(c, room, visual=self.render_mode is not None)  # visual shapes only for rendering
        self.body = p.loadURDF(urdf_path(), [0, 0, 1], physicsClientId=c, flags=p.URDF_USE_INERTIA_FROM_FILE)
        p.changeDynamics(
            self.body, -1, linearDamping=self.damping[0], angularDamping=self.damping[1], physicsClientId=c
        )
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

    _MAX_STATE_DRAWS = 1000

    def _random_state(self, rng) -> np.ndarray:
        assert self.room is not None  # reset builds the room before drawing a state in it
        cells = np.argwhere(self.room.footprint)

        def draw():
            ij = cells[rng.integers(len(cells))]
            xy = self.room.origin + (ij + rng.uniform(0, 1, 2)) * self.room.cell
            z = rng.uniform(0.3, 3.0)
            r, pt = rng.uniform(-0.3, 0.3, 2)
            q = self.p.getQuaternionFromEuler([r, pt, rng.uniform(-np.pi, np.pi)])
            return np.array([xy[0], xy[1], z, *q, *rng.uniform(-1, 1, 3), *rng.uniform(-0.5, 0.5, 3)])

        s = draw_until(draw, self._placed_clear, self._MAX_STATE_DRAWS)
        if s is None:
            raise RuntimeError(f"could not place the quadrotor clear of obstacles in {self._MAX_STATE_DRAWS} draws")
        return s

    def _placed_clear(self, state) -> bool:
        """Put the body in ``state``; whether it is clear of everything there."""
        self.set_state(state)
        return not self.in_contact()

    _MAX_ROOM_DRAWS = 100

    def _draw_room(self, spec) -> Room:
        if spec is None:
            return generate_room(self.np_random)
        if isinstance(spec, Room):
            return spec
        try:
            return generate_room(self.np_random, **spec)
        except (TypeError, ValueError) as e:
            raise ValueError(f"option 'room': {e}") from None

    def _built(self, room: Room) -> Room:
        self._build(room)
        return room

    # ------------------------------------------------------------------ API
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        options = self.check_options(options)
        s = None
        if "state" in options:
            s = option_vector(options["state"], 13, "state", " (position, quaternion xyzw, velocity, angular velocity)")
            if abs(norm(s[3:7]) - 1) > 1e-6:
                raise ValueError(f"option 'state': the quaternion {s[3:7].tolist()} is not a unit quaternion")
        spec = options.get("room")
        if spec is not None and not isinstance(spec, (Room, dict)):
            raise ValueError(
                f"option 'room' must be a Room or a dict of generate_room arguments, got {type(spec).__name__}"
            )
        if s is None:
            self._build(self._draw_room(spec))
            self._random_state(self.np_random)
        elif isinstance(spec, Room):
            self._build(spec)
            if not self._placed_clear(s):
                raise ValueError(f"option 'state': the body at {s[:3].tolist()} is in contact with option 'room'")
        elif (
            draw_until(
                lambda: self._built(self._draw_room(spec)), lambda _: self._placed_clear(s), self._MAX_ROOM_DRAWS
            )
            is None
        ):
            # a generated room (from the seed, or from the given generate_room arguments) is
            # redrawn until the given state is clear of it, as generation keeps states clear
            raise ValueError(
                f"option 'state': the body at {s[:3].tolist()} is in contact with each of "
                f"{self._MAX_ROOM_DRAWS} rooms drawn from the seed; give 'room' too or move the state"
            )
        self.scene = QuadrotorScene(self.room, self.params)
        self._t = 0.0
        self.begin_episode()
        return self._obs(), {"state": self.get_state(), "sim_time": 0.0}

    def rays(self) -> np.ndarray:
        p = self.p
        res = p.rayTestBatch(
            [[0, 0, 0]] * 6,
            (RAY_RANGE * _RAY_DIRS).tolist(),
            parentObjectUniqueId=self.body,
            parentLinkIndex=-1,
            physicsClientId=self.client,
        )
        return np.array([RAY_RANGE * r[2] if r[0] >= 0 else RAY_RANGE for r in res])

    def _obs(self) -> np.ndarray:
        s = self.get_state()
        return np.concatenate([self.rays(), s[3:13]]).astype(np.float32)

    def step(self, action):
        self.check_can_step()
        a = np.asarray(action, dtype=float)
        if a.shape != (4,):
            raise ValueError(f"action must have shape (4,) in {self.action_space}, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite (space {self.action_space}), got {a.tolist()}")
        a = np.clip(a, self.action_space.low, self.action_space.high)
        n, hit = push_body(self.p, self.client, self.body, a, self.n_sub, stop_on_contact=True)
        for _ in range(n):  # summed step by step, as simulated
            self._t += self.params.dt
        truncated = not hit and self._t >= self.max_episode_time - 1e-9
        info = {"state": self.get_state(), "sim_time": self._t}
        if hit or truncated:
            self.end_episode()
            info["outcome"] = "collision" if hit else "timeout"
        return self._obs(), (-1.0 if hit else 0.0), hit, truncated, info

    # ------------------------------------------------------------------ labelling hooks
    def privileged(self) -> dict:
        self.require_episode()
        return {"state": self.get_state(), "room": self.room}

    def sample_states(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """States as the original's datagen drew them (see "Risk labelling" above)."""
        self.require_episode()
        assert self.room is not None  # require_episode raised otherwise
        lo, hi = self.room.bounds()
        span = hi - lo
        lo, hi = lo - 0.15 * span, hi + 0.15 * span

        def draw(r, k):
            q = r.normal(size=(k, 4))
            q /= norms(q, keepdims=True)
            return np.column_stack(
                [r.uniform(lo, hi, (k, 3)), q, r.uniform(-10, 10, (k, 3)), r.uniform(-4 * np.pi, 4 * np.pi, (k, 3))]
            )

        return rejection_sample(
            rng, n, 13, draw, self.risk_scene().collision.states_failed, "quadrotor states clear of the room"
        )

    def observe_states(self, states, rng=None) -> np.ndarray:
        """The 16-dim observation of arbitrary states (PyBullet rays; the env's state is restored);
        ``rng`` is unused (no random feature)."""
        states = unit_quaternion_rows(state_rows(states, 13))
        keep = self.get_state()
        obs = np.empty((len(states), 16), dtype=np.float32)
        for i, st in enumerate(states):
            self.set_state(st)
            obs[i, :6] = self.rays()
            obs[i, 6:] = st[3:13]
        self.set_state(keep)
        return obs

    @property
    def true_state(self) -> np.ndarray:
        return self.get_state()

    def render_frame(self) -> np.ndarray:
        p = self.p
        s = self.get_state()
        view = p.computeViewMatrixFromYawPitchRoll(
            s[:3].tolist(), 4.0, 30.0, -35.0, 0.0, 2, physicsClientId=self.client
        )
        proj = p.computeProjectionMatrixFOV(60.0, 320 / 240, 0.05, 100.0, physicsClientId=self.client)
        _, _, rgba, _, _ = p.getCameraImage(
            320, 240, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=self.client
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(240, 320, 4)[..., :3]

    def close(self):
        super().close()
        if getattr(self, "client", None) is not None:
            try:
                self.p.disconnect(physicsClientId=self.client)
            except Exception:
                pass
            self.client = None
