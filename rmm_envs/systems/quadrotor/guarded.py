"""The quadrotor under parallel autonomy: a reckless pilot, a guardian that may take over.

``QuadrotorRoomGuarded-v0`` (blocking, fixed step) and ``QuadrotorRoomParallel-v0``
(non-blocking: the guardian's thinking time passes in the world), the quadrotor counterparts
of ``Dubins3DMazeGuarded-v0`` / ``Dubins3DMazeParallel-v0`` with the same contract
(:mod:`rmm_envs.autonomy`), so the same guardians and ``rmm-bench --env`` run on them.

## Description

The PyBullet quadrotor of ``QuadrotorRoom-v0`` (0.5 kg, a collision cylinder of radius 0.3 m,
240 Hz physics, the same :class:`~rmm_envs.systems.quadrotor.body.QuadrotorParams`) in a room from
:func:`rmm_envs.systems.quadrotor.rooms.generate_room`, flown by a *command* ``(v_forward, v_left, v_up,
yaw_rate)`` in the body's heading frame.  At every physics step the cascaded controller of
:mod:`rmm_envs.systems.quadrotor.control` turns the command into thrust and body moments (the
velocity loop, then a geometric attitude loop), which PyBullet applies.  A built-in reckless
pilot (:class:`rmm_envs.systems.quadrotor.driver.WaypointPilot`) flies straight through
``n_waypoints`` random points of the room, the last one the goal, ignoring walls and objects:
alone it collides in 57.7% of the episodes and reaches the goal in 42.2% (2,048 episodes of
``rmm-bench`` seed 0, fixed 1 ms clock).  The agent is a *guardian*: at every step it decides
whether to take over the command.

## Action space

``Dict(active_ctrl=Discrete(2), vforward_ctrl=Box(-2, 2, (1,)), vleft_ctrl=Box(-2, 2, (1,)),
vup_ctrl=Box(-1, 1, (1,)), yawrate_ctrl=Box(-1, 1, (1,)))``, a
:class:`rmm_envs.autonomy.GuardianActionSpace` built from the controller's command box
(m/s, m/s, m/s, rad/s).  ``active_ctrl = 0``: the pilot commands this step; ``1``: the
guardian's command is applied, clipped to the box.  NaN/inf, a wrong shape or type, a missing
or unknown field, or an ``active_ctrl`` other than 0/1 raise ``ValueError`` naming the field.
The space's safe default (``space.safe_default``, what ``brakes`` applies) is
:class:`~rmm_envs.systems.quadrotor.control.HoverAndLevel`: the zero command.  The guardian
commands the same controller as the pilot, so the risk labels' random commands, the safe
default and the pilot live in one space.

## Observation space

``Box(23,)`` float32, an :class:`rmm_envs.autonomy.ObservationBox` with a named layout:

| index | field | observation | range |
|---|---|---|---|
| 0-7 | ``rays`` | ray ranges in the body's x-y plane at ``k pi / 4`` from the body x axis, m | [0, ray_range] |
| 8-9 | ``rays_vertical`` | ray ranges along body +z and -z, m | [0, ray_range] |
| 10-13 | ``orientation`` | quaternion (x, y, z, w), world frame | [-1, 1] |
| 14-16 | ``velocity`` | linear velocity in the heading frame (forward, left, up), m/s | R |
| 17-19 | ``angular_velocity`` | angular velocity in the body frame, rad/s | R |
| 20-22 | ``goal_offset`` | goal minus position in the heading frame, m | R |

Rays start at the body's origin (PyBullet ``rayTestBatch``, not hitting the body itself) and
read ``ray_range`` (10 m) when nothing is nearer.

## Dynamics and episode end

Each interval holds one command: the pilot's (chosen from the state at the interval's start)
or the guardian's.  An interval of ``d`` seconds runs the PyBullet steps that bring the
physics clock to ``floor(t / dt)`` steps at simulated time ``t`` (so fractional steps carry
over).  ``+1`` when the body comes within ``goal_radius`` of the goal (checked after every
physics step), ``-1`` on any contact with the room (walls, objects, floor; PyBullet's contact
points, queried at every physics step of an interval unless the body's clearance at the
interval's start, :meth:`RoomCollision.clearance <rmm_envs.systems.quadrotor.room_collision.RoomCollision.clearance>`,
exceeds what it can travel in the interval, ``|v| d + (F_max / m + g) d^2 / 2`` plus 5 cm; the
clearance is recomputed only when the last one, less the distance moved since, falls short);
the episode ends on either (``terminated``), else ``truncated`` at
``max_episode_sim_time`` (60 s).  The state after a collision is the one PyBullet reached.

## Starting state

A room from the seed; the body level and still at a point uniform over the room's footprint at
a height ``U(altitude)`` (0.5-2 m), its bounding sphere (radius 0.304 m) clear of everything by
0.2 m, with a uniform yaw; ``n_waypoints`` (3) points drawn the same way with 0.5 m of
clearance, each at least ``min_leg`` (3 m) horizontally from the one before.  Draws that miss
the clearance are redrawn, so starts lie at least 0.504 m and waypoints at least 0.804 m above
the floor (``altitude``'s maximum must exceed 0.804).  A room where they cannot be placed in
200 draws each is redrawn (up to 100 rooms; then ``RuntimeError`` naming ``min_leg`` and
``altitude``).  ``reset(seed=..., options={"room": Room or dict of generate_room arguments,
"state": [13 numbers], "waypoints": [[x, y, z], ...]})`` sets any of them.  A given state must
lie over the room's footprint and clear of it; given waypoints must lie over the footprint with
the bounding sphere clear of the floor, walls and objects (generated rooms are redrawn until
they are; a given room, or a room with a given state, raises; a point no higher than the
bounding radius raises at once, as no room can hold it).  Those, a non-unit quaternion,
an unknown key or malformed values raise ``ValueError`` naming the option.

## Risk labelling

The :class:`rmm_envs.risk.LabelledEnv` hooks: ``risk_scene()`` is the episode's
:class:`rmm_envs.scenes.QuadrotorCommandScene`: the estimator's controls are random commands
uniform over the command box, each held for one tree level, flown through the same controller
(compiled, pinned to the numpy propagator that reproduces PyBullet), failing on the analytic
room collision.  ``sample_states(rng, n)`` draws flight states: a point uniform over the
footprint at height ``U(0.2, 3)`` m, a uniform yaw, roll and pitch ``U(-0.3, 0.3)`` rad,
heading-frame velocity ``U(-2, 2)`` m/s horizontally and ``U(-1, 1)`` vertically, angular
velocity ``U(-1, 1)`` rad/s per axis, rejecting states in contact.  ``observe_states`` is this
env's observation of them (PyBullet rays; the goal offset from the episode's goal).

## Info

Every step: ``sim_time``, ``state`` (13 numbers, **privileged**), ``active`` and ``control``
(the command applied), ``cost`` (1.0 on the step that collides, else 0.0) and
``nominal_control`` (also on ``reset``): the pilot's command at the state the returned
observation shows, exactly what it applies if the guardian leaves it the next interval.  On
the last step also ``outcome`` (``"goal"``, ``"collision"`` or ``"timeout"``) and
``episode_stats`` (the statistics of :class:`rmm_envs.envs.guarded.GuardedEnv`,
``final_speed`` the body's speed).  :meth:`QuadrotorRoomGuardedEnv.privileged` returns the
state, the room, the goal, the waypoints and the simulated time.

## Arguments

``gym.make("QuadrotorRoomGuarded-v0", step_dt=0.1, max_episode_sim_time=60.0, n_waypoints=3,
altitude=(0.5, 2.0), min_leg=3.0, goal_radius=0.5, cruise_speed=1.5, climb_speed=0.5,
ray_range=10.0, clock=None, render_mode=None, disturbances=None)``; ``cruise_speed`` and
``climb_speed`` (m/s) are the pilot's.  ``disturbances``: sensor noise (rays, orientation,
velocities, goal offset), ray dropouts, actuation error on the command, wind and pushes (an
acceleration of the body, ``vx``, ``vy``, ``vz`` in m/s^2, applied in PyBullet as a world force
at the centre of mass), or a body whose ``mass`` and ``linear_damping`` differ from what the
controller assumes (:mod:`rmm_envs.disturbances`; off by default).
``gym.make("QuadrotorRoomParallel-v0", time_accel=10.0, base_step=0.1, clock=None, **same but step_dt)``:
the same world under :class:`rmm_envs.wrappers.NonBlockingStepping`
(each ``step(a)`` advances the world by ``elapsed * time_accel + base_step`` seconds under the
previous action, then stores ``a``; the first interval is the pilot's).

## Rendering

``render_mode="rgb_array"``: a 320 x 240 frame from PyBullet's software renderer, as
``QuadrotorRoom-v0``.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox
from rmm_envs.catalog import system
from rmm_envs.clocks import make_clock
from rmm_envs.envs.base import check_arguments, finite, whole
from rmm_envs.envs.guarded import GuardedEnv, Motion, parallel_twin
from rmm_envs.machine_independent import matvec, norm
from rmm_envs.systems.quadrotor.closed_loop import ClosedLoopQuadrotor
from rmm_envs.systems.quadrotor.control import (
    CommandController,
    command_wrench,
    yaw_of,
)
from rmm_envs.systems.quadrotor.driver import WaypointPilot
from rmm_envs.systems.quadrotor.env import QuadrotorRoomEnv
from rmm_envs.systems.quadrotor.observation import (
    _CONTACT_MARGIN,
    _DIRS,
    _GOAL,
    _LAYOUT,
    _QUAT,
    _RANGES,
    _RATES,
    _VEL,
    QuadrotorDatasetHooks,
    observation_layout,
)
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_envs.systems.quadrotor.rotations import quat_to_rot
from rmm_envs.systems.quadrotor.scene import QuadrotorCommandScene
from rmm_envs.systems.quadrotor.starts import WAYPOINT_CLEARANCE, QuadrotorRoomStarts

__all__ = ["CONTROLS", "QuadrotorRoomGuardedEnv", "parallel_env", "observation_layout"]

from rmm_envs.systems.quadrotor.control import CONTROLS, DYNAMICS_NAME  # noqa: E402  (owned by the system; re-exported)


class QuadrotorRoomGuardedEnv(QuadrotorRoomStarts, QuadrotorDatasetHooks, GuardedEnv, QuadrotorRoomEnv):
    """Blocking quadrotor parallel-autonomy env; see the module docstring for the full spec."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}
    reset_options: tuple[str, ...] = ("room", "state", "waypoints")
    #: a rate disturbance accelerates the body (m/s^2, world frame): wind, pushes
    disturbance_rates = {"vx": 7, "vy": 8, "vz": 9}

    def disturbance_parameters(self) -> dict[str, float]:
        """What a ``mismatch`` scales in PyBullet (the controller keeps the nominal values): the
        body's mass and its linear damping."""
        return {"mass": float(self.params.mass), "linear_damping": float(self.damping[0])}

    def __init__(
        self,
        step_dt: float = 0.1,
        max_episode_sim_time: float = 60.0,
        n_waypoints: int = 3,
        altitude=(0.5, 2.0),
        min_leg: float = 3.0,
        goal_radius: float = 0.5,
        cruise_speed: float = 1.5,
        climb_speed: float = 0.5,
        ray_range: float = 10.0,
        clock=None,
        render_mode: str | None = None,
        disturbances=None,
    ) -> None:
        alt = tuple(altitude) if isinstance(altitude, (tuple, list, np.ndarray)) else ()
        check_arguments(
            [
                (finite(step_dt) and step_dt > 0, "step_dt", step_dt, "a finite number of seconds > 0"),
                (
                    finite(max_episode_sim_time) and max_episode_sim_time > 0,
                    "max_episode_sim_time",
                    max_episode_sim_time,
                    "a finite number of seconds > 0 (episodes need a time limit)",
                ),
                (
                    whole(n_waypoints) and n_waypoints >= 1,
                    "n_waypoints",
                    n_waypoints,
                    "an integer >= 1 (the last is the goal)",
                ),
                (
                    len(alt) == 2
                    and all(finite(a) for a in alt)
                    and 0.35 <= alt[0] <= alt[1]
                    and alt[1] > WAYPOINT_CLEARANCE + BOUND,
                    "altitude",
                    altitude,
                    f"a pair (min, max) of heights in m with 0.35 <= min <= max and max > {WAYPOINT_CLEARANCE + BOUND:.3f} "
                    f"(a drawn waypoint keeps its bounding sphere {WAYPOINT_CLEARANCE} m above the floor)",
                ),
                (finite(min_leg) and min_leg >= 0, "min_leg", min_leg, "a finite number of metres >= 0"),
                (finite(goal_radius) and goal_radius > 0, "goal_radius", goal_radius, "a finite number of metres > 0"),
                (finite(cruise_speed) and cruise_speed > 0, "cruise_speed", cruise_speed, "a finite speed > 0 (m/s)"),
                (finite(climb_speed) and climb_speed > 0, "climb_speed", climb_speed, "a finite speed > 0 (m/s)"),
                (finite(ray_range) and ray_range > 0, "ray_range", ray_range, "a finite number of metres > 0"),
            ]
        )
        QuadrotorRoomEnv.__init__(self, render_mode=render_mode)
        self.step_dt = float(step_dt)
        self.max_episode_sim_time = float(max_episode_sim_time)
        self.n_waypoints = int(n_waypoints)
        self.altitude = (float(alt[0]), float(alt[1]))
        self.min_leg, self.goal_radius, self.ray_range = float(min_leg), float(goal_radius), float(ray_range)
        self.controller = CommandController(self.params)
        self.dynamics = ClosedLoopQuadrotor(self.controller)
        self.pilot = WaypointPilot(self.dynamics.control_low, self.dynamics.control_high, cruise_speed, climb_speed)
        self.clock = make_clock(clock)
        self.action_space = GuardianActionSpace.for_dynamics(
            self.dynamics,
            CONTROLS,
            safe_default=system("QuadrotorRoom").make_safe_default(),
            dynamics_name=DYNAMICS_NAME,
        )
        low, high = np.full(_LAYOUT.size, -np.inf, np.float32), np.full(_LAYOUT.size, np.inf, np.float32)
        low[_RANGES], high[_RANGES] = 0.0, self.ray_range
        low[_QUAT], high[_QUAT] = -1.0, 1.0
        self.observation_space = ObservationBox(low, high, _LAYOUT)
        self.set_disturbances(disturbances)
        # F_max / m + g: no body acceleration exceeds it (damping only slows the body)
        self._a_bound = self.params.control_high[0] / self.params.mass + self.params.gravity
        self._ray_to = (self.ray_range * _DIRS).tolist()
        self._wrench = np.empty(4)
        self.goal = np.zeros(3)

    def begin(self, options: dict) -> np.ndarray:
        room, state, waypoints = self.draw_start(options)
        self._build(room)
        self.set_state(state)
        self.scene = QuadrotorCommandScene(room, self.controller)
        self.pilot.reset(waypoints)
        self.goal = waypoints[-1].copy()
        self._physics_steps = 0
        self._gap, self._gap_at = -math.inf, state[:3].copy()  # no clearance known yet
        self._observed = state  # the start as drawn (PyBullet's copy of it may differ in the last bit)
        return state

    def begin_plant(self, parameters: dict[str, float] | None) -> None:
        self._mass = self.params.mass
        if parameters is not None:
            self._mass = parameters["mass"]
            self.p.changeDynamics(
                self.body,
                -1,
                mass=parameters["mass"],
                linearDamping=parameters["linear_damping"],
                physicsClientId=self.client,
            )

    # ------------------------------------------------------------------ stepping
    def rays(self) -> np.ndarray:
        res = self.p.rayTestBatch(
            [[0.0, 0.0, 0.0]] * len(_DIRS),
            self._ray_to,
            parentObjectUniqueId=self.body,
            parentLinkIndex=-1,
            physicsClientId=self.client,
        )
        return np.array([self.ray_range * r[2] if r[0] >= 0 else self.ray_range for r in res])

    def _observe(self, s) -> np.ndarray:
        """:meth:`_features` of one state, in scalar arithmetic (a step's observation; the tests
        hold the two equal)."""
        out = np.empty(_LAYOUT.size, dtype=np.float32)
        out[_RANGES] = self.rays()
        out[_QUAT] = s[3:7]
        psi = yaw_of(s[3], s[4], s[5], s[6])
        c, sn = math.cos(psi), math.sin(psi)
        out[_VEL] = (c * s[7] + sn * s[8], -sn * s[7] + c * s[8], s[9])
        out[_RATES] = matvec(quat_to_rot(s[3:7]).T, s[10:13])
        dx, dy = self.goal[0] - s[0], self.goal[1] - s[1]
        out[_GOAL] = (c * dx + sn * dy, -sn * dx + c * dy, self.goal[2] - s[2])
        return self.sensed(out, self._sim_time)

    def observe(self) -> np.ndarray:
        return self._observe(self._observed)

    def advance(self, duration: float, active: bool, control) -> Motion:
        """PyBullet's steps of ``params.dt`` up to the interval's end under one held command
        (the pilot's, or ``control`` clipped to the command box), stopped at the first contact
        or arrival."""
        p, c, body, par = self.p, self.client, self.body, self.params
        s = self.get_state()
        if active:
            cmd = np.minimum(
                np.maximum(np.asarray(control, dtype=float).reshape(4), self.dynamics.control_low),
                self.dynamics.control_high,
            )
        else:
            cmd = self._nominal.copy()
        push, a_bound = None, self._a_bound
        if self.moves_plant:  # the actuators' command; wind and pushes as a world force
            cmd = self.actuated(cmd, self._sim_time)
            rate = self.drift(self._sim_time, 13)
            if rate is not None and rate[7:10].any():
                push, a_bound = tuple(self._mass * rate[7:10]), a_bound + norm(rate[7:10])
        target = math.floor((self._sim_time + duration) / par.dt + 1e-9)
        n = max(0, target - self._physics_steps)
        t = n * par.dt
        speed = math.sqrt(s[7] ** 2 + s[8] ** 2 + s[9] ** 2)
        reach = speed * t + 0.5 * a_bound * t * t + _CONTACT_MARGIN
        # the clearance is 1-Lipschitz in the position: the last one computed, less the distance
        # moved since, is a lower bound; compute it afresh only when that bound is not enough
        query = self._gap - math.dist(s[:3], self._gap_at) <= reach
        if query:
            assert self.scene is not None  # set by reset; simulate runs within an episode
            self._gap, self._gap_at = self.scene.collision.clearance(s[:3]), s[:3].copy()
            query = self._gap <= reach
        k, w, gx, gy, gz = self.controller.packed, self._wrench, *self.goal
        r2 = self.goal_radius**2
        hit = reached = False
        frame, force, torque, step = p.LINK_FRAME, p.applyExternalForce, p.applyExternalTorque, p.stepSimulation
        pose, vel, contacts, origin = (
            p.getBasePositionAndOrientation,
            p.getBaseVelocity,
            p.getContactPoints,
            (0.0, 0.0, 0.0),
        )
        for _ in range(n):
            command_wrench(s, cmd, k, w)
            force(body, -1, (0.0, 0.0, w[0]), origin, frame, physicsClientId=c)
            torque(body, -1, (w[1], w[2], w[3]), frame, physicsClientId=c)
            if push is not None:  # at the centre of mass, in the world frame
                force(body, -1, push, (s[0], s[1], s[2]), p.WORLD_FRAME, physicsClientId=c)
            step(physicsClientId=c)
            self._physics_steps += 1
            hit = query and len(contacts(bodyA=body, physicsClientId=c)) > 0
            pos, quat = pose(body, physicsClientId=c)
            s = np.array(pos + quat + sum(vel(body, physicsClientId=c), ()))
            if hit:
                break
            if (pos[0] - gx) ** 2 + (pos[1] - gy) ** 2 + (pos[2] - gz) ** 2 < r2:
                reached = True
                break
        self._observed = s
        return Motion("collision" if hit else "goal" if reached else None, cmd, s)

    def driver_control(self) -> np.ndarray:
        return self.pilot.command(self.get_state())

    def final_speed(self) -> float:
        v = self.get_state()[7:10]
        return norm(v)

    # ------------------------------------------------------------------ accessors and labelling hooks
    def privileged(self) -> dict:
        """The true state, the room, the goal, the waypoints and the simulated time. **Privileged**."""
        self.require_episode()
        return {
            "state": self.get_state(),
            "room": self.room,
            "goal": self.goal.copy(),
            "waypoints": self.pilot.waypoints.copy(),
            "sim_time": self._sim_time,
        }

    true_state = property(lambda self: self.get_state(), doc="The true state (a copy). **Privileged**.")
    sim_time = property(lambda self: self._sim_time, doc="Simulated seconds since reset.")


parallel_env = parallel_twin(QuadrotorRoomGuardedEnv, "QuadrotorRoomParallel-v0")
