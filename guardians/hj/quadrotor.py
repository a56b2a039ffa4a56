"""The ``hj`` guardian on the quadrotor (``QuadrotorRoomParallel-v0``): a 4-D avoid value of the
horizontal flight in each leg's altitude band.

``hj`` serves three systems: :class:`guardians.hj.guardian.HJGuardian` hands an env whose action
space has the quadrotor's four commands (:data:`rmm_envs.envs.quadrotor_room_parallel.CONTROLS`)
to :class:`QuadrotorHJGuardian` (``quadrotor``, a dict, sets its own arguments).  It uses
**privileged** information: the room, the waypoints, the true state and the simulated time.

## The model

The guardian commands the cascaded controller's velocity reference.  Its velocity loop makes
the horizontal acceleration ``k_v (v_ref - v)`` (``k_v = 2.5`` 1/s), of norm at most
``a_max_h = 5`` m/s^2 (:class:`rmm_envs.systems.quadrotor_control.CommandController`), so the
commanded flight is, horizontally, a point mass with a bounded acceleration.  Its velocity in
polar form, speed ``v`` and direction ``theta``, is exactly the Dubins4D car:
``x' = v cos theta, y' = v sin theta, theta' = u1, v' = u2``, with ``u2`` the acceleration along
the velocity and ``v u1`` the one across it.  The value is solved for ``|u2| <= accel`` (2.5
m/s^2) and ``|u1| <= turn_rate`` (1 rad/s, so ``v u1 <= 3`` m/s^2 up to ``v_max = 3`` m/s): at
most ``sqrt(2.5^2 + 3^2) = 3.9`` m/s^2, inside what the controller gives.  At ``v = 0`` the
direction turns freely, as a point mass starts off in any direction.  So the solve reuses the
Dubins4D solver and its compiled kernel unchanged (``Dubins4DHJ(u1_max=turn_rate, u2_max=accel,
v_min=0, v_max=v_max)``).

The vertical is decoupled.  The rooms have no ceiling, the objects stand on the floor, and the
pilot flies straight from waypoint to waypoint, so on each **leg** (start to the first
waypoint, then waypoint to waypoint) its height stays between the leg's ends.  Each leg gets a
value over its **altitude band**, the ends' heights widened by ``band_margin`` (0.3 m: the
body's half height 0.05 m, its rim rising 0.14 m at a 27-degree tilt, and 0.1 m of vertical
tracking).  The obstacles are what reaches into the band: a wall box whose top reaches the
band, as its exact rectangle; an object by the least of its exact 3-D signed distances at
heights 0.1 m apart through the band, less 0.05 m (the distance is 1-Lipschitz in height), a
lower bound on the horizontal distance to its cross-sections there.  The target is that signed
distance less the body's bounding radius (0.304 m), in metres; the floor is left to the
vertical (the guardian keeps the pilot's vertical command).  Each leg's grid covers the leg's
box plus ``pad`` (3 m), clipped to the walls' extent: ``spacing`` 0.3 m (walls are 0.5 m thick,
so each has nodes inside), ``n_heading`` 16, speed ``[0, 3]`` m/s in ``n_speed`` 7 nodes,
``horizon`` 2 s (braking from 3 m/s takes 1.2 s).  The guardian follows the pilot's leg by the
pilot's own rule (a waypoint within ``reach``, 0.5 m, is passed).  A body below its band, or
outside its leg's grid, has no value: control is left to the pilot and counted
(``outside_band``, ``outside_grid``); above the band the value is still conservative.

## Error margin

``margin`` (``None``: half a position cell plus ``tracking``, 0.25 m) is what the value may
over-state: multilinear interpolation at a kink (half a cell, 0.15 m) plus the error of the
prediction below (``tracking = 0.1`` m).  Measured on 858 steps of 0.1 s of
``QuadrotorRoomGuarded-v0`` (12 episodes, the pilot's command or a random one): the closed form
predicts the position to 6 mm (median), 3.6 cm (99th percentile), 4.2 cm at worst, and the
velocity to 0.75 m/s at worst just after a command jump (the attitude loop's lag), about 0.08 m
more over a second lap.

## The rule: act in time for the one-step latency

A command returned at ``s_k`` acts from ``s_{k+1}`` on; the lap from ``s_k`` runs under the
previous command (the guardian's, if it acted, else the pilot's, ``info["nominal_control"]``).
The guardian predicts the state one lap ahead under that pending command and one more lap under
the pilot's nominal command, with the velocity loop's closed form (``v(t) = c + (v0 - c)
e^{-k_v t}`` per horizontal axis and its integral; the lap measured from the simulated times,
0.1 s before the first).  If the value there is above ``margin`` (``margin + hysteresis`` while
it is in control, ``hysteresis`` 0.15 m: no flicker at the level set) it leaves control to the
pilot.  Otherwise it commands, from the state one lap ahead, the least invasive of these whose
value one lap later is above ``margin``:

1. **slide**: the pilot's speed along the level line of ``V``, on the side the pilot's command
   leans to when the guardian takes over (the left of ``grad V`` head-on), kept until it hands
   back, plus ``2 (margin + hysteresis - V)`` m/s (at most 1) up the gradient: the body goes
   round the obstacle on that level, as a bug algorithm follows a boundary, and the pilot takes
   over again once its own command is safe;
2. the slide blended with the value's optimal command at 1/3 and 2/3;
3. the **optimal** command: the bang-bang maximiser of ``grad V . f`` as an acceleration ``a``,
   commanded as the reference ``v + 2 a / k_v`` (twice the velocity loop's step, so that the lag
   still gives at least ``a`` over a lap), clipped to the command box.

The vertical command is the pilot's and the yaw rate 0 (the heading frame stays put).  The
counts of slides and optimal commands are in ``stats()``.

Explicit edge cases: a state with NaN applies the env's safe default (hover) and is counted
(``nan_states``); a room with no walls, or an ``info`` without four finite numbers in
``nominal_control``, is refused with ``ValueError`` naming it.
"""

from __future__ import annotations

import math

import numpy as np

from guardians._checks import finite, integer, quadrotor_only
from guardians.base import Guardian
from guardians.hj.cache import ValueCache, load_or_solve
from guardians.hj.dynamics import Dubins4DHJ
from guardians.hj.grid import Grid, central_gradient
from guardians.hj.solver import check_scheme, select_backend, solve_brt
from guardians.hj.room import lag_prediction, room_target
from rmm_envs.portable import arctan2
from rmm_envs.systems.quadrotor_control import CommandController, yaw_of
from rmm_envs.worlds.room_collision import BOUND

__all__ = ["QuadrotorHJGuardian"]


class QuadrotorHJGuardian(Guardian):
    """Grid HJ reachability guardian for the quadrotor; see the module docstring."""

    name = "hj"
    observation_type = "global"
    privileged = True

    def __init__(self, spacing: float = 0.3, n_heading: int = 16, n_speed: int = 5, v_max: float = 2.0,
                 accel: float = 2.5, turn_rate: float = 1.0, horizon: float = 1.2, pad: float | None = 3.0,
                 band_margin: float = 0.1, reach: float = 0.5, order: int = 2, rk: int = 3, cfl: float = 0.8, margin: float | None = None,
                 tracking: float = 0.1, hysteresis: float = 0.15, delay: int = 1, lap: float | None = None,
                 n_directions: int = 16, min_speed: float = 0.5, clear_time: float = 1.0, side_memory: float = 3.0,
                 cache_dir=None, cache: bool = True, cache_max_files: int = 64, backend: str = "auto",
                 threads: int | None = None) -> None:
        super().__init__()
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
        self.threads = None if threads is None else integer("threads", threads, 1, "or None")
        if backend not in ("auto", "numpy", "numba"):
            raise ValueError(f"backend must be one of ('auto', 'numpy', 'numba'), got {backend!r}")
        self.backend = backend
        self.cache = ValueCache(cache_dir, integer("cache_max_files", cache_max_files, 1)) if cache else None
        self.dynamics = Dubins4DHJ(u1_max=self.turn_rate, u2_max=self.accel, v_min=0.0, v_max=self.v_max)
        self._counts = self._zero()
        self.solve_seconds = 0.0
        self.V = None

    @staticmethod
    def _zero() -> dict:
        return {"outside_grid": 0, "outside_band": 0, "nan_states": 0, "cache_hits": 0, "solves": 0, "nominal": 0,
                "turns": 0, "optimal": 0, "takeovers": 0}

    def check_spaces(self, observation_space, action_space) -> None:
        quadrotor_only(self, action_space)

    # ------------------------------------------------------------------ the value
    def band(self, a, b) -> tuple[float, float]:
        """The altitude band ``(z_lo, z_hi)`` of the leg from point ``a`` to ``b`` (module docstring)."""
        return min(float(a[2]), float(b[2])) - self.band_margin, max(float(a[2]), float(b[2])) + self.band_margin

    def region_grid(self, room, a, b) -> Grid:
        """The grid over the box of the leg from ``a`` to ``b`` plus ``pad``, clipped to the walls'
        extent (``pad=None``: the walls' extent, the whole room)."""
        pts = np.array([[float(a[0]), float(a[1])], [float(b[0]), float(b[1])]])
        lo_w, hi_w = room.bounds()
        if self.pad is None:
            lo, hi = np.minimum(lo_w[:2], pts.min(0) - self.spacing), np.maximum(hi_w[:2], pts.max(0) + self.spacing)
        else:
            lo = np.maximum(pts.min(0) - self.pad, np.minimum(lo_w[:2], pts.min(0) - self.spacing))
            hi = np.minimum(pts.max(0) + self.pad, np.maximum(hi_w[:2], pts.max(0) + self.spacing))
        n = [max(3, int(math.ceil((hi[k] - lo[k]) / self.spacing)) + 1) for k in range(2)]
        return Grid([lo[0], lo[1], -math.pi, 0.0], [hi[0], hi[1], math.pi, self.v_max],
                    [n[0], n[1], self.n_heading, self.n_speed], periodic=[2])

    def spec(self, room, grid: Grid, z_lo: float, z_hi: float) -> dict:
        walls = np.asarray(room.walls, float).reshape(-1, 6)
        objects = [[o["shape"], *(np.round(np.asarray(o[k], float), 9).tolist() for k in ("pos", "quat", "size"))]
                   for o in room.objects]
        return {"system": "quadrotor-horizontal", "dynamics": self.dynamics.key(), "grid": grid.key(),
                "horizon": self.horizon, "order": self.order, "rk": self.rk, "cfl": self.cfl, "band": [round(z_lo, 9), round(z_hi, 9)],
                "radius": BOUND, "walls": np.round(walls, 9).tolist(), "objects": objects, "version": 2}

    def value_function(self, room, grid: Grid, z_lo: float, z_hi: float) -> np.ndarray:
        """The avoid value of the room's cross-sections at the band on ``grid`` (cached)."""
        def solve():
            return solve_brt(grid, self.dynamics, room_target(grid, room, z_lo, z_hi), self.horizon, order=self.order,
                             rk=self.rk, cfl=self.cfl, backend=self.backend, threads=self.threads)[0]

        V, seconds = load_or_solve(self.cache or None, self.spec(room, grid, z_lo, z_hi), grid.shape, solve, self._counts)
        if seconds is not None:
            self.solve_seconds += seconds
        return V

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        priv = self._privileged()
        room = priv["room"]
        if np.asarray(room.walls).size == 0:
            raise ValueError(f"guardian {self.name!r} (quadrotor) needs a room with walls, got none")
        state = np.asarray(priv["state"], float)
        self._counts = self._zero()
        self.solve_seconds = 0.0
        self.waypoints = np.asarray(priv["waypoints"], float).reshape(-1, 3)
        points = [state[:3], *self.waypoints]
        self._legs = []  # per leg: (band, grid, V, interpolator of V and its gradient)
        for a, b in zip(points[:-1], points[1:]):
            band, grid = self.band(a, b), self.region_grid(room, a, b)
            select_backend(grid, self.dynamics, self.order, self.backend)
            V = self.value_function(room, grid, *band)
            self._legs.append((band, grid, V, grid.interpolator([V, *central_gradient(V, grid)])))
        self.leg = -1
        self._next_leg(state)
        self._margin = (0.5 * float(max(self.grid.dx[0], self.grid.dx[1])) + self.tracking if self.margin is None
                        else self.margin)
        ctrl = CommandController()
        self.k_v = float(ctrl.k_v)
        space = self.action_space
        self._lo, self._hi = np.asarray(space.control_low, float), np.asarray(space.control_high, float)
        self._safe = space.safe_default.policy(space, self.rng) if space.safe_default is not None else None
        self._last_time = None
        self._measured_lap = None
        self._held = None  # the command the guardian returned last step (None: it was inactive)
        self._side = None  # the side it turns the pilot's command to while in control (+1: counter-clockwise)
        self._last_turn = None  # (x, y, side) where it last turned the pilot's command
        self._hit = math.inf  # distance to the pilot's waypoint where the guardian took over
        self._turn = 0  # the turn (in steps of 2 pi / n_directions) of its last command from the pilot's

    def _next_leg(self, state) -> None:
        """Follow the pilot's leg: past a waypoint within ``reach`` of it, as the pilot counts."""
        leg = max(self.leg, 0)
        while leg < len(self.waypoints) - 1 and math.dist(tuple(state[:3]), tuple(self.waypoints[leg])) < self.reach:
            leg += 1
        if leg != self.leg:
            self.leg = leg
            self.z_band, self.grid, self.V, self._interp = self._legs[leg]

    # ------------------------------------------------------------------ the decision
    def current_lap(self) -> float:
        if self.lap is not None:
            return self.lap
        return self._measured_lap if self._measured_lap is not None else 0.1

    def evaluate(self, x, y, vx, vy) -> np.ndarray:
        """``(V, dV/dx, dV/dy, dV/dtheta, dV/dv)`` at position ``(x, y)`` and world velocity
        ``(vx, vy)`` (a speed above the grid's ``v_max`` is read at ``v_max``)."""
        th = _angle(vy, vx)
        return self._interp(np.array([x, y, th, min(math.sqrt(vx * vx + vy * vy), self.v_max)]))

    def inside(self, x, y, vx, vy) -> bool:
        return bool(self.grid.contains(np.array([x, y, 0.0, min(math.sqrt(vx * vx + vy * vy), self.v_max)])))

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
        if not np.all(np.isfinite(s)):
            self._counts["nan_states"] += 1
            u = self._safe(observation) if self._safe is not None else np.zeros(4)
            return self.action_space.active(u)
        nominal = _command(info)
        leg = self.leg
        self._next_leg(s)
        if not (self.z_band[0] - self.band_margin <= s[2] <= self.z_band[1] + self.band_margin):
            self._counts["outside_band"] += 1
            return self.action_space.inactive()
        psi = yaw_of(*s[3:7])
        c, sn = math.cos(psi), math.sin(psi)
        lap = self.current_lap()
        h0 = (s[0], s[1], s[7], s[8])
        pending = held if held is not None else nominal
        h1 = self.predict(h0, pending, c, sn, lap * self.delay)
        h2 = self.predict(h1, nominal, c, sn, lap)
        if not (self.inside(*h0) and self.inside(*h2)):
            self._counts["outside_grid"] += 1
            return self.action_space.inactive()
        if held is None:
            if float(self.evaluate(*h2)[0]) > self._margin:
                return self.action_space.inactive()
            self._counts["takeovers"] += 1
            self._hit = self._to_waypoint(h0)
        elif self.leg != leg:  # a waypoint passed while in control: progress counts to the next
            self._hit = self._to_waypoint(h0)
        elif self.hands_back(h1, h2, nominal, c, sn, lap):
            self._side, self._turn = None, 0
            return self.action_space.inactive()
        cmd = self._choose(h1, nominal, c, sn, lap)
        self._held = cmd
        return self.action_space.active(cmd)

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
            base = _angle(-gy, -gx)
        elif speed > 1e-9:
            base = _angle(ny, nx)
        elif gx != 0.0 or gy != 0.0:
            base = _angle(gy, gx)  # no pilot command: away from the obstacle
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
            return self._full(self._clip(self._optimal(h1, vals, c, s)), nominal)
        self._counts["nominal" if k == 0 else "turns"] += 1
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

    def _optimal(self, h1, vals, c, s):
        """The value's optimal command (bang-bang in the polar velocity), heading frame."""
        gx, gy = float(vals[1]), float(vals[2])
        vx, vy = h1[2], h1[3]
        sp = math.sqrt(vx * vx + vy * vy)
        ex, ey = (vx / sp, vy / sp) if sp > 1e-9 else (c, s)
        u1 = self.turn_rate if vals[3] >= 0 else -self.turn_rate
        u2 = self.accel if vals[4] >= 0 else -self.accel
        if sp <= 1e-9:  # at rest: accelerate straight up the position gradient
            gn = math.sqrt(gx * gx + gy * gy)
            ex, ey, u2, u1 = (gx / gn, gy / gn, self.accel, 0.0) if gn > 0 else (ex, ey, 0.0, 0.0)
        ax, ay = u2 * ex - sp * u1 * ey, u2 * ey + sp * u1 * ex
        ox, oy = vx + 2.0 * ax / self.k_v, vy + 2.0 * ay / self.k_v
        on = math.sqrt(ox * ox + oy * oy)
        if on > self.v_max:  # the value knows no faster flight
            ox, oy = ox * self.v_max / on, oy * self.v_max / on
        return (c * ox + s * oy, -s * ox + c * oy)

    def _clip(self, hc):
        return (min(max(hc[0], self._lo[0]), self._hi[0]), min(max(hc[1], self._lo[1]), self._hi[1]))

    def _full(self, hc, nominal) -> np.ndarray:
        return np.array([hc[0], hc[1], min(max(nominal[2], self._lo[2]), self._hi[2]), 0.0])

    def stats(self) -> dict:
        return dict(self._counts, solve_seconds=self.solve_seconds)


def _angle(y: float, x: float) -> float:
    """The direction of ``(x, y)`` (the portable arctan2: the same bits on every machine)."""
    return float(arctan2(np.array([y]), np.array([x]))[0])


def _command(info) -> np.ndarray:
    """``info["nominal_control"]`` as four finite numbers, refused (naming it) otherwise."""
    if not isinstance(info, dict) or "nominal_control" not in info:
        raise ValueError("guardian 'hj' (quadrotor) needs info['nominal_control'] from the env (the pilot's command), "
                         f"got {sorted(info) if isinstance(info, dict) else type(info).__name__}")
    u = np.asarray(info["nominal_control"], float).reshape(-1)
    if u.shape != (4,) or not np.all(np.isfinite(u)):
        raise ValueError(f"info['nominal_control'] must be four finite numbers (forward, left, up, yaw rate), "
                         f"got {info['nominal_control']!r}")
    return u
