"""The ``hj`` guardian on the quadrotor (``QuadrotorRoomParallel-v0``): a 4-D avoid value of the
horizontal flight in each leg's altitude band, and a climb over what blocks the way.

:class:`rmm_guardians.hj.guardian.HJGuardian` hands an env whose action space states the quadrotor's
dynamics to :class:`QuadrotorHJGuardian` (``quadrotor``, a dict, sets its arguments).  It is
**privileged**: it reads the room, the waypoints, the true state and the simulated time.  Model:
the velocity loop as a point mass with bounded acceleration (in polar velocity form the Dubins4D
car), solved by the project's compiled solver over the whole room in each leg's altitude band;
``margin`` (0.25 m) is what the value may over-state.  Rule: take over when the value two laps
ahead is at most the margin; in control, the safe command nearest the pilot's (one side, turns
coming back a step a lap, boundary following until nearer the waypoint); after ``climb_after``
(2 s) in control, a climb over the obstacles near the line to the waypoint if one is clear below
``climb_ceiling`` (:mod:`rmm_guardians.hj.quadrotor_climb`); hand back once nearer, clear by a
hysteresis and safe for 1 s more under the pilot's command.  NaN states apply the hover default.
In full: :class:`QuadrotorHJGuardian`; why: docs/decisions/0013-hj-quadrotor.md.
"""

from __future__ import annotations

import math

import numpy as np

from rmm_envs.systems.quadrotor.control import CONTROLS, CommandController, yaw_of
from rmm_guardians._checks import finite, integer
from rmm_guardians.hj.cache import ValueCache
from rmm_guardians.hj.dynamics import Dubins4DHJ
from rmm_guardians.hj.quadrotor_climb import Climb
from rmm_guardians.hj.quadrotor_values import LegValues
from rmm_guardians.hj.room import angle, lag_prediction, nominal_command, optimal_command
from rmm_guardians.hj.settings import disturbance_setting
from rmm_guardians.hj.solver import check_scheme
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import quadrotor_only

__all__ = ["QuadrotorHJGuardian"]


class QuadrotorHJGuardian(LegValues, PrivilegedGuardian):
    """Grid HJ reachability guardian for the quadrotor; see the module docstring.

    **Model**: the velocity loop makes the horizontal acceleration ``k_v (v_ref - v)`` (2.5 /s),
    of norm at most 5 m/s^2: a point mass with bounded acceleration, in polar velocity form
    exactly the Dubins4D car (``Dubins4DHJ(u1_max=turn_rate, u2_max=accel, v_min=0,
    v_max=v_max)``), inside what the controller gives (``v u1 <= 2`` m/s^2 up to ``v_max``).  A
    faster state is read at ``v_max``.  ``horizon`` 1.2 s: braking from ``v_max`` takes 0.8 s and a
    body at rest stays safe (2.0 s moved the value by at most 0.1 m).  The vertical is decoupled:
    on each **leg** the body's centre stays between the ends' heights widened by ``band_margin``;
    the target over that band is a wall box whose top reaches it (its exact rectangle) or an
    object (the least of its exact 3-D signed distances at heights 0.1 m apart through the band,
    less 0.05 m), less the body's bounding radius (0.304 m).  A leg whose ends differ by more than
    ``2 band_margin`` gets a second value over its arrival band (the end's height
    +-``2 band_margin``), used within ``1.5 band_margin`` of that height.  Grid (``pad=None``):
    the walls' extent, the whole room (a leg's box plus 3 m cut detours off), ``spacing`` 0.3 m,
    ``n_heading`` 16, speeds ``[0, 2]`` m/s in ``n_speed`` 5 nodes.  A body outside its band or
    off the grid has no value: control is left to the pilot (``outside_band``, ``outside_grid``).

    **Margin** (``None``: half a position cell plus ``tracking``, 0.25 m): what the value may
    over-state, interpolation at a kink (0.15 m) plus the prediction's error: on 858 steps of
    0.1 s of ``QuadrotorRoomGuarded-v0`` (12 episodes, the pilot's command or a random one) the
    closed form predicts the position to 6 mm (median), 3.6 cm (99th percentile), 4.2 cm at worst.

    **Rule**: predict the state one lap ahead under the pending command (``h1``) and one more
    under the pilot's (``h2``), with the velocity loop's closed form (``v(t) = c + (v0 - c)
    e^{-k_v t}`` per axis); take over when ``V(h2) <= margin``.  In control command the safe
    command nearest the pilot's: its horizontal command (at least ``min_speed``, at most
    ``v_max``) turned by the least multiple of ``2 pi / n_directions`` toward one side (chosen at
    the takeover, reused within ``side_memory``) whose predicted state is on the grid above
    ``margin``; the scan starts one step short of the last turn (turns come back a step a lap) and,
    until the body is nearer the waypoint than where it took over, from straight at the obstacle
    (boundary following).  Hand back once nearer, ``V(h2) > margin + hysteresis`` and the pilot's
    command, held, stays above ``margin`` for ``clear_time``.  No safe direction: the value's
    optimal command (the bang-bang acceleration ``a``, commanded as ``v + 2 a / k_v``).  After
    ``climb_after`` in control: a climb (:mod:`rmm_guardians.hj.quadrotor_climb`, ``climb_margin``,
    ``climb_ceiling``, ``climb_speed``).  ``stats()`` counts takeovers, kept commands, turns,
    optimal commands, climbs and climbing steps.  NaN states hover (``nan_states``); a room with no
    walls or a malformed ``nominal_control`` is refused with ``ValueError``.  No disturbance is
    modelled (wind is a force on the velocities, through the velocity loop, beside mass and damping
    mismatch; not ``hj.disturbance``'s position-rate bound): one other than 0 is refused on its env."""

    name = "hj"
    #: as a part of its method (rmm_guardians.parts): what it models, its controls, its settings field
    serves, controls, option = "the quadrotor", CONTROLS, "quadrotor"
    observation_type = "global"
    privileged = True

    def __init__(
        self,
        spacing: float = 0.3,
        n_heading: int = 16,
        n_speed: int = 5,
        v_max: float = 2.0,
        accel: float = 2.5,
        turn_rate: float = 1.0,
        horizon: float = 1.2,
        pad: float | None = None,
        band_margin: float = 0.1,
        reach: float = 0.5,
        order: int = 2,
        rk: int = 3,
        cfl: float = 0.8,
        margin: float | None = None,
        tracking: float = 0.1,
        hysteresis: float = 0.15,
        delay: int = 1,
        lap: float | None = None,
        n_directions: int = 16,
        min_speed: float = 0.5,
        clear_time: float = 1.0,
        side_memory: float = 3.0,
        climb_after: float | None = 2.0,
        climb_margin: float = 0.15,
        climb_ceiling: float = 6.0,
        climb_speed: float = 1.0,
        cache_dir=None,
        cache: bool = True,
        cache_max_files: int = 64,
        backend: str = "auto",
        threads: int | None = None,
        disturbance: float | str = 0.0,
    ) -> None:
        super().__init__()
        self.disturbance = disturbance_setting(disturbance)  # refused on the quadrotor unless 0: see above
        self.spacing = finite("spacing", spacing, 0.0, lo_open=True)
        self.n_heading = integer("n_heading", n_heading, 3)
        self.n_speed = integer("n_speed", n_speed, 3)
        self.v_max = finite("v_max", v_max, 0.0, lo_open=True)
        self.accel = finite("accel", accel, 0.0, lo_open=True)
        self.turn_rate = finite("turn_rate", turn_rate, 0.0, lo_open=True)
        self.horizon = finite("horizon", horizon, 0.0, lo_open=True)
        self.pad = None if pad is None else finite("pad", pad, 0.0)
        self.band_margin = finite("band_margin", band_margin, 0.0)
        self.reach = finite("reach", reach, 0.0, lo_open=True)
        self.order, self.rk, self.cfl = check_scheme(order, rk, cfl)
        self.margin = None if margin is None else finite("margin", margin)
        self.tracking = finite("tracking", tracking, 0.0)
        self.hysteresis = finite("hysteresis", hysteresis, 0.0)
        self.delay = integer("delay", delay, 0, "laps between a decision and its effect")
        self.lap = None if lap is None else finite("lap", lap, 0.0, lo_open=True)
        self.n_directions = integer("n_directions", n_directions, 4)
        self.min_speed = finite("min_speed", min_speed, 0.0, lo_open=True)
        self.clear_time = finite("clear_time", clear_time, 0.0)
        self.side_memory = finite("side_memory", side_memory, 0.0)
        self.climb_after = None if climb_after is None else finite("climb_after", climb_after, 0.0)
        self.climb_margin = finite("climb_margin", climb_margin, 0.0, lo_open=True)
        self.climb_ceiling = finite("climb_ceiling", climb_ceiling, 0.0, lo_open=True)
        self.climb_speed = finite("climb_speed", climb_speed, 0.0, lo_open=True)
        self.threads = None if threads is None else integer("threads", threads, 1, "or None")
        if backend not in ("auto", "numpy", "numba"):
            raise ValueError(f"backend must be one of ('auto', 'numpy', 'numba'), got {backend!r}")
        self.backend = backend
        self.cache = ValueCache(cache_dir, integer("cache_max_files", cache_max_files, 1)) if cache else None
        self.dynamics = Dubins4DHJ(u1_max=self.turn_rate, u2_max=self.accel, v_min=0.0, v_max=self.v_max)
        self._counts = self._zero()
        self.solve_seconds = 0.0
        self.V: np.ndarray | None = None
        self._probe: tuple | None = None  # the last decision's predicted horizontal state (signals())

    @staticmethod
    def _zero() -> dict:
        return {
            "outside_grid": 0,
            "outside_band": 0,
            "nan_states": 0,
            "cache_hits": 0,
            "solves": 0,
            "nominal": 0,
            "turns": 0,
            "optimal": 0,
            "takeovers": 0,
            "climbs": 0,
            "climb_steps": 0,
        }

    def check_spaces(self, observation_space, action_space) -> None:
        quadrotor_only(self, action_space)
        if self.disturbance != 0.0:
            raise ValueError(
                f"guardian {self.name!r} (quadrotor) models no disturbance, got disturbance={self.disturbance!r}: "
                "the quadrotor's wind is a force on its velocities, not a bound on its position rates"
            )

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        room = priv["room"]
        if np.asarray(room.walls).size == 0:
            raise ValueError(f"guardian {self.name!r} (quadrotor) needs a room with walls, got none")
        state = np.asarray(priv["state"], float)
        self._counts = self._zero()
        self.solve_seconds = 0.0
        self.waypoints = np.asarray(priv["waypoints"], float).reshape(-1, 3)
        self._legs = self.leg_values(room, [state[:3], *self.waypoints])
        self.leg = -1
        self._next_leg(state)
        self._margin = (
            0.5 * float(max(self.grid.dx[0], self.grid.dx[1])) + self.tracking if self.margin is None else self.margin
        )
        ctrl = CommandController()
        self.k_v = float(ctrl.k_v)
        space = self.action_space
        assert space is not None  # check_spaces refused anything but the quadrotor's GuardianActionSpace
        self._lo, self._hi = np.asarray(space.control_low, float), np.asarray(space.control_high, float)
        self._safe = space.safe_default.policy(space, self.rng) if space.safe_default is not None else None
        self._last_time = None
        self._measured_lap = None
        self._held = None  # the command the guardian returned last step (None: it was inactive)
        # the side it turns the pilot's command to while in control (+1: counter-clockwise)
        self._side: float | None = None
        # (x, y, side) where it last turned the pilot's command
        self._last_turn: tuple[float, float, float] | None = None
        self._hit = math.inf  # distance to the pilot's waypoint where the guardian took over
        self._turn = 0  # the turn (in steps of 2 pi / n_directions) of its last command from the pilot's
        self._climb = (
            None
            if self.climb_after is None
            else Climb(room, self.climb_margin, self.climb_ceiling, self.climb_speed, self.k_v)
        )
        self._plan = None  # the climb in progress (rmm_guardians.hj.quadrotor_climb)
        self._in_control = 0.0  # the simulated time (s) it has been in control since it took over

    # ------------------------------------------------------------------ the decision
    def predict(self, h, cmd, c, s, t):
        """The horizontal state ``h = (x, y, vx, vy)`` after ``t`` s under heading-frame command
        ``cmd`` (forward, left), with heading ``(c, s) = (cos psi, sin psi)``."""
        cx, cy = c * cmd[0] - s * cmd[1], s * cmd[0] + c * cmd[1]
        x, vx = lag_prediction(h[0], h[2], cx, self.k_v, t)
        y, vy = lag_prediction(h[1], h[3], cy, self.k_v, t)
        return (x, y, vx, vy)

    def act(self, observation, info=None):
        s = self._state_and_lap()
        held, self._held = self._held, None
        self._probe = None
        if not np.all(np.isfinite(s)):
            self._counts["nan_states"] += 1
            u = self._safe(observation) if self._safe is not None else np.zeros(4)
            return self.action_space.active(u)
        nominal = nominal_command(info)
        leg = self.leg
        self._next_leg(s)
        psi = yaw_of(*s[3:7])
        c, sn = math.cos(psi), math.sin(psi)
        if self._plan is not None:  # climbing: flown to its end, then handed back
            return self._climbing(s, c, sn)
        if not (self.z_band[0] - self.band_margin <= s[2] <= self.z_band[1] + self.band_margin):
            self._counts["outside_band"] += 1
            return self.action_space.inactive()
        lap = self.current_lap()
        h0 = (s[0], s[1], s[7], s[8])
        pending = held if held is not None else nominal
        h1 = self.predict(h0, pending, c, sn, lap * self.delay)
        h2 = self.predict(h1, nominal, c, sn, lap)
        if not (self.inside(*h0) and self.inside(*h2)):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        self._probe = h2
        if held is None:
            if float(self.evaluate(*h2)[0]) > self._margin:
                return self.action_space.inactive()
            self._counts["takeovers"] += 1
            self._hit = self._to_waypoint(h0)
            self._in_control = 0.0
        elif self.leg != leg:  # a waypoint passed while in control: progress counts to the next
            self._hit = self._to_waypoint(h0)
        elif self.hands_back(h1, h2, nominal, c, sn, lap):
            self._side, self._turn = None, 0
            return self.action_space.inactive()
        else:
            self._in_control += lap
        if self._climb is not None and self._in_control >= self.climb_after:
            self._plan = self._climb.plan(s[:2], h1[:2], h1[2:], s[2], self.waypoints[self.leg])
            if self._plan is not None:
                self._counts["climbs"] += 1
                return self._climbing(s, c, sn)
        cmd = self._choose(h1, nominal, c, sn, lap)
        self._held = cmd
        return self.action_space.active(cmd)

    def _climbing(self, s, c, sn):
        """The climb's command (heading frame, no yaw), or the pilot's control once it is over."""
        v = self._climb.command(self._plan, s[0], s[1], s[2], s[7], s[8])
        if v is None:
            self._plan, self._side, self._turn = None, None, 0
            return self.action_space.inactive()
        self._counts["climb_steps"] += 1
        hc = self._clip((c * v[0] + sn * v[1], -sn * v[0] + c * v[1]))
        self._held = np.array([hc[0], hc[1], min(max(v[2], self._lo[2]), self._hi[2]), 0.0])
        return self.action_space.active(self._held)

    def _to_waypoint(self, h) -> float:
        """Horizontal distance from ``h`` to the pilot's waypoint."""
        w = self.waypoints[self.leg]
        return math.hypot(h[0] - w[0], h[1] - w[1])

    def hands_back(self, h1, h2, nominal, c, s, lap) -> bool:
        """While in control: give the pilot back its command once (a) the body is nearer the
        pilot's waypoint than where the guardian took over (as a bug algorithm leaves an
        obstacle's boundary only nearer the goal than where it met it: handed back sooner, the
        pilot flies back at the obstacle and the boundary is followed round again), (b) the value
        after the pilot's next lap is above ``margin + hysteresis`` and (c) its command, held,
        keeps the value above ``margin`` for ``clear_time`` more."""
        if self._to_waypoint(h2) >= self._hit or float(self.evaluate(*h2)[0]) <= self._margin + self.hysteresis:
            return False
        h = h2
        for _ in range(int(math.ceil(self.clear_time / lap - 1e-9))):
            h = self.predict(h, nominal, c, s, lap)
            if not self.inside(*h) or float(self.evaluate(*h)[0]) <= self._margin:
                return False
        return True

    def _choose(self, h1, nominal, c, s, lap) -> np.ndarray:
        """The safe command nearest the pilot's (module docstring): the pilot's horizontal
        command turned toward the guardian's side by the least multiple of ``2 pi /
        n_directions`` (from one step less than its last turn) whose predicted state after the
        lap it governs is on the grid with a value above ``margin``, at the pilot's speed (at
        least ``min_speed``, at most ``v_max``); if none, the value's optimal command."""
        nx, ny = c * nominal[0] - s * nominal[1], s * nominal[0] + c * nominal[1]  # world frame
        speed = math.sqrt(nx * nx + ny * ny)
        vals = self.evaluate(*h1)
        gx, gy = float(vals[1]), float(vals[2])
        follow = self._to_waypoint(h1) >= self._hit and (gx != 0.0 or gy != 0.0)
        if follow:  # not nearer the waypoint than where it took over: follow the obstacle's boundary
            base = angle(-gy, -gx)
        elif speed > 1e-9:
            base = angle(ny, nx)
        elif gx != 0.0 or gy != 0.0:
            base = angle(gy, gx)  # no pilot command: away from the obstacle
        else:
            base = 0.0
        speed = min(max(speed, self.min_speed), self.v_max)

        def first_safe(side, k0):
            for k in range(k0, self.n_directions):
                ang = base + side * k * 2.0 * math.pi / self.n_directions
                wx, wy = speed * math.cos(ang), speed * math.sin(ang)
                hc = self._clip((c * wx + s * wy, -s * wx + c * wy))
                h = self.predict(h1, hc, c, s, lap)
                if self.inside(*h) and float(self.evaluate(*h)[0]) > self._margin:  # off the grid: no value, not safe
                    return k, hc
            return None, None

        if self._side is None:
            self._side = self._choose_side(h1, first_safe)
        k, hc = first_safe(self._side, max(0, self._turn - 1))
        if k is None:
            self._counts["optimal"] += 1
            return self._full(
                self._clip(optimal_command(h1, vals, c, s, self.turn_rate, self.accel, self.k_v, self.v_max)), nominal
            )
        self._counts["nominal" if k == 0 and not follow else "turns"] += 1
        self._turn = k
        if k:
            self._last_turn = (h1[0], h1[1], self._side)
        return self._full(hc, nominal)

    def _choose_side(self, h1, first_safe) -> float:
        """The side the pilot's command is turned to, kept while in control: the side it turned
        to last time if that was within ``side_memory`` of here (turning the other way would send
        the body back and forth along an obstacle whose far end the pilot points past), else the
        side with the smaller turn to a safe command (counter-clockwise on a tie)."""
        last = self._last_turn
        if last is not None and math.hypot(h1[0] - last[0], h1[1] - last[1]) <= self.side_memory:
            return last[2]
        left, right = first_safe(1.0, 0)[0], first_safe(-1.0, 0)[0]
        if left is None or right is None:
            return 1.0 if right is None else -1.0
        return 1.0 if left <= right else -1.0

    def _clip(self, hc):
        return (min(max(hc[0], self._lo[0]), self._hi[0]), min(max(hc[1], self._lo[1]), self._hi[1]))

    def _full(self, hc, nominal) -> np.ndarray:
        return np.array([hc[0], hc[1], min(max(nominal[2], self._lo[2]), self._hi[2]), 0.0])

    def stats(self) -> dict:
        return dict(self._counts, solve_seconds=self.solve_seconds)

    def signals(self) -> dict[str, float]:
        """``value``: the avoid value ``V`` of the current leg's walls (m) at the horizontal state
        predicted one lap after the pending command (the state the takeover rule reads; 1000 where
        the band holds nothing), ``nan``
        where the last decision read none (outside the height band or the grid, climbing, a
        non-finite state, before a decision); ``value_threshold``: the value at or below which
        it takes over.  Interpolated here from the stored prediction: never changes a decision."""
        line = float(self._margin) if self.V is not None else math.nan
        if self._probe is None:
            return {"value": math.nan, "value_threshold": line}
        return {"value": float(self.evaluate(*self._probe)[0]), "value_threshold": line}

    def alarm(self) -> tuple[float, float]:
        """``(-value, -value_threshold)`` of :meth:`signals`: up when the value is below its line."""
        s = self.signals()
        return -s["value"], -s["value_threshold"]
