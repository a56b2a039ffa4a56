"""The ``cbf`` guardian on the quadrotor (``QuadrotorRoomParallel-v0``, ``QuadrotorRoomGuarded-v0``).

:class:`rmm_guardians.cbf.guardian.CBFGuardian` hands an env whose action space is of the
quadrotor's dynamics (``"quadrotor"``) to :class:`QuadrotorCBFGuardian`, also usable (and named,
``rmm_guardians.cbf.quadrotor:QuadrotorCBFGuardian``) on its own.  It reads **privileged** data
(the room, the true body state, the sim time) and filters the pilot's velocity command,
``info["nominal_control"]``, with HOCBF rows on the room's floor, walls and objects (a
first-order model of the velocity loop, :mod:`rmm_guardians.cbf.quadrotor_rows`), for the state
one lap ahead, sliding along a shape when the filter deadlocks.

Offers :class:`QuadrotorCBFGuardian` (the model, the QP and the defaults in its docstring); why:
docs/decisions/0016-cbf-quadrotor.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from rmm_envs.systems.quadrotor.control import CONTROLS, CommandController, body_packed, body_step, command_wrench
from rmm_envs.systems.quadrotor.room_collision import BOUND
from rmm_guardians._checks import finite, integer
from rmm_guardians.cbf.backend import parse_solver
from rmm_guardians.cbf.quadrotor_rows import CommandQP, command_rows, room_shapes
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import quadrotor_only

__all__ = ["QuadrotorCBFGuardian"]

njit: Callable[..., Any] | None  # numba's, or None where numba is missing
try:
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; the Python loop still works
    njit = None


def _flow(s, cmd, k, body, steps, a, b, u):
    """The body state after ``steps`` physics steps of the controller (gains ``k``) and the body
    (``body``) under the held command ``cmd`` from ``s`` (``a``, ``b``, ``u``: work arrays); the
    per-step arithmetic of :class:`rmm_envs.systems.quadrotor.closed_loop.ClosedLoopQuadrotor`."""
    for j in range(13):
        a[j] = s[j]
    for _ in range(steps):
        command_wrench(a, cmd, k, u)
        body_step(a, u, body, b)
        a, b = b, a
    return a.copy()


if njit is not None:
    _flow = njit(cache=True)(_flow)


class QuadrotorCBFGuardian(PrivilegedGuardian):
    """HOCBF safety filter of the quadrotor's velocity command; see the module docstring.

    **Model**: the guardian issues what the pilot issues, a velocity command
    ``u = (u_forward, u_left, u_up)`` in the heading frame (and a yaw rate), and the body's world
    velocity tracks the commanded one, ``w``, as a first-order lag ``v' = (w - v) / tau``:
    ``tau_h = 0.42`` s, ``tau_z = 0.34`` s, measured on the controller and body
    (``ClosedLoopQuadrotor`` from hover, steps of 1 and 2 m/s forward and 0.5 and 1 m/s up: 63% of
    the step after 0.42-0.43 s and 0.34 s, settling 3-5% short).  Each part of the room is a
    convex shape with signed distance ``d``; its barrier ``b = d - rho``, ``rho = body_radius``
    (0.304 m: the collision cylinder in any attitude) ``+ margin``, gives one HOCBF row per shape
    (:func:`rmm_guardians.cbf.quadrotor_rows.command_rows`), for the ``n_rows`` nearest shapes.

    **QP** over ``(u, s)``: minimise ``|u - u_nom|^2 + slack_weight s^2`` under ``G u - s <= h``,
    the command box and ``s = 0``.  A nominal command that satisfies every row passes unsolved.
    It takes control when a row is active at the solution (``|h_i - G_i u*| <= active_atol``).
    Infeasible or failed: the same QP with ``s >= 0`` (the command violating the worst row least,
    ``qp_fallbacks``); should that fail too, hover (``hover_fallbacks``).  In control it commands
    a zero yaw rate (a yaw rate would turn the held command in the world during the lap).

    **Deadlock escape**: when the strict QP leaves the pilot's command (at least ``2 v_stuck``
    horizontally) under ``v_stuck`` of horizontal speed, its reference becomes ``v_slide`` along
    the horizontal tangent of the nearest shape with a mostly horizontal normal (``|n_h| >= 0.5``),
    on the side the pilot's command leans to (kept while it follows), with the pilot's climb
    rate; it hands back once the pilot's command satisfies every row and no longer points into
    that shape.  Blocked again within ``slide_memory`` of where it last followed, it goes on the
    same way.  Entries are counted in ``slides``.

    **Latency**: the rows are written at the state predicted one lap ahead under the command
    acting during the lap, through the compiled controller and body steps (whole physics steps,
    ``ceil(lap / dt)``); the lap from the simulated times, ``lap_guess`` before the first.

    Defaults: ``p1 = p2 = 3`` /s, ``margin = 0.05`` m, ``v_slide = 1.5`` m/s (the pilot's
    cruise speed), ``v_stuck = 0.25`` m/s, ``slide_memory = 3`` m, ``n_rows = 8``,
    ``slack_weight = 1e3`` (1e4 leaves OSQP at its iteration limit on a plain two-wall case,
    tested), ``eps = 1e-6``, ``active_atol = 1e-3``.  NaN states hover (``nan_states``); bad
    arguments are refused naming the value; a command box without 0 is refused at ``reset``."""

    name = "cbf"
    #: as a part of its method (rmm_guardians.parts): what it models, its controls, its settings field
    serves, controls, option = "the quadrotor", CONTROLS, "quadrotor"

    def __init__(
        self,
        p1: float = 3.0,
        p2: float = 3.0,
        margin: float = 0.05,
        tau_h: float = 0.42,
        tau_z: float = 0.34,
        body_radius: float = BOUND,
        n_rows: int = 8,
        slack_weight: float = 1e3,
        active_atol: float = 1e-3,
        predict_latency: bool = True,
        lap_guess: float = 0.1,
        eps: float = 1e-6,
        solver: str = "osqp",
        v_stuck: float = 0.25,
        v_slide: float = 1.5,
        slide_memory: float = 3.0,
    ) -> None:
        super().__init__()
        self.p1 = finite("p1 (class-K gain)", p1, 0.0, lo_open=True)
        self.p2 = finite("p2 (class-K gain)", p2, 0.0, lo_open=True)
        self.margin = finite("margin", margin, 0.0)
        self.tau_h = finite("tau_h (horizontal velocity lag, s)", tau_h, 0.0, lo_open=True)
        self.tau_z = finite("tau_z (vertical velocity lag, s)", tau_z, 0.0, lo_open=True)
        self.body_radius = finite("body_radius", body_radius, 0.0)
        self.n_rows = integer("n_rows", n_rows, 1, "how many of the nearest shapes get a barrier row")
        self.slack_weight = finite("slack_weight", slack_weight, 0.0, lo_open=True)
        self.active_atol = finite("active_atol", active_atol, 0.0)
        self.predict_latency = bool(predict_latency)
        self.lap_guess = finite("lap_guess", lap_guess, 0.0, lo_open=True)
        self.eps = finite("eps", eps, 0.0, lo_open=True)
        self.v_stuck = finite("v_stuck", v_stuck, 0.0)
        self.v_slide = finite("v_slide (0: no deadlock escape)", v_slide, 0.0)
        self.slide_memory = finite("slide_memory", slide_memory, 0.0)
        self._solver_name = parse_solver(solver)
        self.solver = solver
        controller = CommandController()
        self._gains, self._body, self._dt = controller.packed, body_packed(controller.params), controller.params.dt
        self._counts = self._zero()
        self._barrier_min = math.nan  # the last decision's smallest barrier value (signals())

    @staticmethod
    def _zero() -> dict:
        return {"qp_fallbacks": 0, "hover_fallbacks": 0, "nan_states": 0, "qp_solves": 0, "slides": 0}

    @property
    def rho(self) -> float:
        """The distance from a shape at which a barrier is 0: ``body_radius + margin``."""
        return self.body_radius + self.margin

    def check_spaces(self, observation_space, action_space) -> None:
        quadrotor_only(self, action_space)

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        space = quadrotor_only(self, self.action_space)
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        if "room" not in priv:
            raise ValueError(
                f"guardian {self.name!r} (quadrotor) needs the room in the env's privileged data (keys: {sorted(priv)})"
            )
        self.shapes = room_shapes(priv["room"])
        self.lo = np.asarray(space.control_low, float)
        self.hi = np.asarray(space.control_high, float)
        self.K = min(self.n_rows, len(self.shapes))
        self._qp = CommandQP(self.K, self.lo[:3], self.hi[:3], self.slack_weight, self.eps, self._solver_name)
        self._counts = self._zero()
        self._barrier_min = math.nan  # the last decision's smallest barrier value (signals())
        self._pending = None  # the guardian's command acting during the coming lap; None: the pilot's
        self.start_laps(self.lap_guess, since=priv.get("sim_time", 0.0))
        self._side = 0  # 0: filtering the nominal; +-1: following a shape (the deadlock escape), on that side
        # (x, y, side) of the last step spent following a shape
        self._followed: tuple[float, float, int] | None = None
        self._normal = (0.0, 0.0)  # the horizontal normal of the shape followed (heading frame)

    # ------------------------------------------------------------------ the maths
    def rows(self, state):
        """``(b, G, h)`` of the ``n_rows`` shapes nearest the body at ``state`` (13 numbers),
        smallest ``b`` first, over the heading-frame command (:mod:`rmm_guardians.cbf.quadrotor_rows`)."""
        b, G, h, _ = command_rows(state, self.shapes, self.K, self.rho, self.tau_h, self.tau_z, self.p1, self.p2)
        return b, G, h

    def predict(self, state, command, lap: float) -> np.ndarray:
        """The body state after ``lap`` seconds of ``command`` (4 numbers, clipped to the box)
        from ``state``, through the controller and the body (whole physics steps)."""
        cmd = np.minimum(np.maximum(np.asarray(command, float), self.lo), self.hi)
        steps = math.ceil(lap / self._dt - 1e-9)
        return _flow(
            np.ascontiguousarray(state, dtype=float)[:13],
            cmd,
            self._gains,
            self._body,
            steps,
            np.empty(13),
            np.empty(13),
            np.empty(4),
        )

    # ------------------------------------------------------------------ the decision
    def _emit(self, u) -> dict:
        cmd = np.minimum(np.maximum(np.r_[np.asarray(u, float)[:3], 0.0], self.lo), self.hi)
        self._pending = cmd
        assert self.action_space is not None  # checked at reset (quadrotor_only)
        return self.action_space.active(cmd)

    def _hover(self) -> dict:
        return self._emit(np.zeros(3))

    def nominal(self, info) -> np.ndarray:
        """The pilot's command this step, ``info["nominal_control"]`` (4 finite numbers; a
        ``ValueError`` naming the key otherwise)."""
        u = None if not isinstance(info, dict) else info.get("nominal_control")
        if u is None:
            raise ValueError(
                f"guardian {self.name!r} (quadrotor) filters the pilot's command, info['nominal_control'] "
                f"(the parallel-autonomy contract), but the step's info has none (keys: "
                f"{sorted(info) if isinstance(info, dict) else info!r})"
            )
        arr = np.asarray(u, dtype=float).reshape(-1)
        if arr.shape != (4,) or not all(map(math.isfinite, arr.tolist())):
            raise ValueError(
                f"info['nominal_control'] must be 4 finite numbers (v_forward, v_left, v_up, yaw_rate), got {u!r}"
            )
        return arr

    def act(self, observation, info=None):
        u_nom = self.nominal(info)
        priv = self._privileged()
        state = np.asarray(priv["state"], float)
        if not self.finite_state(state, 13):
            return self._hover()
        if self.predict_latency:
            self.measure_lap(priv)
            during = self._pending if self._pending is not None else u_nom
            state = self.predict(state, during, self._measured_lap)
        return self.decide(state, u_nom)

    def slide_reference(self, b, G, u) -> np.ndarray | None:
        """The deadlock escape's reference (module docstring): ``v_slide`` along the horizontal
        tangent ``side (-n_y, n_x)`` (heading frame) of the shape being followed, the nominal's
        climb rate ``u[2]``; ``None`` when no row (barrier values ``b``, rows ``G``, nearest
        first) has a mostly horizontal normal (``|n_h| >= 0.5``)."""
        # unit horizontal normals of the shapes within 0.5 m of the nearest such one
        near: list[tuple[float, float, float]] = []
        for bj, (g0, g1, _) in zip(b.tolist(), G.tolist(), strict=True):
            nx, ny = -g0 * self.tau_h, -g1 * self.tau_h  # n_h in the heading frame (G = -n_h / tau_h)
            r = math.hypot(nx, ny)
            if r >= 0.5 and (not near or bj <= near[0][0] + 0.5):
                near.append((bj, nx / r, ny / r))
        if not near:
            return None
        _, nx, ny = near[0]
        tx, ty = -self._side * ny, self._side * nx
        ahead = min(near, key=lambda c: c[1] * tx + c[2] * ty)  # a shape across the way: a concave corner
        self._normal = (nx, ny)
        if ahead[1] * tx + ahead[2] * ty < -0.3:
            tx, ty = -self._side * ahead[2], self._side * ahead[1]  # follow it instead, on the same side
            self._normal = (ahead[1], ahead[2])
        return np.array([tx * self.v_slide, ty * self.v_slide, u[2]])

    def _solve(self, G, h, ref):
        """The strict QP's command for ``ref`` and whether a barrier row is active there, or the
        recovery's command (``active`` true), or ``None`` (both failed)."""
        self._counts["qp_solves"] += 1
        z = self._qp.solve(G, h, ref)
        if z is None:
            self._counts["qp_fallbacks"] += 1
            z = self._qp.solve(G, h, ref, relaxed=True)
            return (None, True) if z is None else (z, True)
        gaps = h - (G[:, 0] * z[0] + G[:, 1] * z[1] + G[:, 2] * z[2])
        return z, bool(np.any(np.abs(gaps) <= self.active_atol))

    def _satisfies(self, G, h, u) -> bool:
        """Whether the command ``u`` satisfies every row ``G u <= h`` (within the QP's tolerance)."""
        return all(
            g0 * u[0] + g1 * u[1] + g2 * u[2] <= hi + self.eps
            for (g0, g1, g2), hi in zip(G.tolist(), h.tolist(), strict=True)
        )

    def decide(self, state, u_nom) -> dict:
        """The decision for the state the command will act from (already predicted)."""
        b, G, h = self.rows(state)
        self._barrier_min = float(b[0]) if len(b) else math.nan
        u = np.minimum(np.maximum(np.asarray(u_nom, float)[:3], self.lo[:3]), self.hi[:3])
        free = self._satisfies(G, h, u)
        if (
            free
            and self._side != 0
            and (self.slide_reference(b, G, u) is None or self._normal[0] * u[0] + self._normal[1] * u[1] >= 0.0)
        ):
            self._side = 0  # free, and no longer pushing into the shape it follows: the escape is over
        if free and self._side == 0:
            self._pending = None  # the nominal satisfies every row: it is the solution, the pilot keeps control
            assert self.action_space is not None  # checked at reset (quadrotor_only)
            return self.action_space.inactive()
        if self._side == 0:
            z, active = self._solve(G, h, u)
            if z is None:
                self._counts["hover_fallbacks"] += 1
                return self._hover()
            if not active:
                self._pending = None
                assert self.action_space is not None  # checked at reset (quadrotor_only)
                return self.action_space.inactive()
            if self.v_slide == 0 or math.hypot(z[0], z[1]) >= self.v_stuck or math.hypot(u[0], u[1]) < 2 * self.v_stuck:
                return self._emit(z)
            # deadlocked: the rows leave the pilot's command almost no horizontal speed.  Follow
            # the blocking shape, on the side the nominal leans to, until the nominal is free
            self._side = 1
            t = self.slide_reference(b, G, u)
            if t is None:  # blocked from above or below only: nothing to follow
                self._side = 0
                return self._emit(z)
            last = self._followed
            if last is not None and math.hypot(state[0] - last[0], state[1] - last[1]) < self.slide_memory:
                self._side = last[2]  # blocked again near where the last escape left off: go on the same way
            else:
                self._side = 1 if t[0] * u[0] + t[1] * u[1] >= 0.0 else -1
            self._counts["slides"] += 1
        self._followed = (float(state[0]), float(state[1]), self._side)
        ref = self.slide_reference(b, G, u)
        if ref is None:  # nothing left to follow: filter the nominal again
            self._side = 0
            ref = u
        z = ref if self._satisfies(G, h, ref) else self._solve(G, h, ref)[0]
        if z is None:
            self._counts["hover_fallbacks"] += 1
            return self._hover()
        return self._emit(z)

    def stats(self) -> dict:
        return dict(self._counts)

    def signals(self) -> dict[str, float]:
        """``barrier_min``: the smallest barrier value of the last decision's rows (nearest shape
        first; ``nan`` before one); ``qp_fallbacks``: the episode's infeasible QPs so far."""
        return {"barrier_min": self._barrier_min, "qp_fallbacks": float(self._counts["qp_fallbacks"])}

    def alarm(self) -> tuple[float, float]:
        """``(-barrier_min, 0)``: up when the last decision's smallest barrier value is below 0."""
        return -float(self._barrier_min), 0.0
