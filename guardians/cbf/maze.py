"""The ``cbf`` guardian on the maze car (``Dubins3DMazeParallel-v0``): walls as control barriers.

:class:`rmm_guardians.cbf.guardian.CBFGuardian` hands an env whose action space is of the maze car's
dynamics (``"dubins3d"``) to :class:`MazeCBFGuardian`, also usable (and named,
``rmm_guardians.cbf.maze:MazeCBFGuardian``) on its own.  It reads **privileged** data (the maze, the
true pose, the car's speed, the sim time) and keeps the driver's turn rate as close as barriers
on the nearest walls allow, for the pose one lap ahead; the barriers include the turn the
constant-speed car needs to keep off a wall.

Offers :class:`MazeCBFGuardian`, :func:`wall_rows` (the barrier rows of a pose) and
:class:`WallQP`.  The barriers: :func:`wall_rows`; the defaults: :class:`MazeCBFGuardian`; why:
docs/decisions/0015-cbf-maze-turning-barrier.md.
"""

from __future__ import annotations

import math

import numpy as np
import osqp
import scipy.sparse as sp

from rmm_envs.systems.maze.dynamics import CONTROLS
from rmm_guardians._checks import finite, integer
from rmm_guardians.cbf.backend import QpsolversQP, parse_solver
from rmm_guardians.privileged import PrivilegedGuardian
from rmm_guardians.system_checks import maze_car_only

__all__ = ["MazeCBFGuardian", "WallQP", "wall_rows"]

BARRIERS = ("turning", "distance")
#: What the QP keeps the turn rate close to: 0, holding the heading (the default, measured safer on
#: the maze: module docstring), or the driver's ``info["nominal_control"]`` (a filter of its turn).
MAZE_REFERENCES = ("hold", "nominal")


def wall_rows(
    state,
    speed: float,
    walls: np.ndarray,
    half: float,
    margin: float,
    p1: float,
    p2: float,
    barrier: str = "turning",
    u_max: float = 0.2,
):
    """The barrier values and the rows ``G u <= h`` (``G`` of shape ``(W, 1)``) of every wall
    ``(W, 4)`` at pose ``state``: ``barrier="turning"`` (the default, first order, gain ``p1``)
    or ``"distance"`` (the high-order distance barrier, gains ``p1, p2``).

    The car ``x' = s cos psi, y' = s sin psi, psi' = u``; a wall is the capsule of points within
    ``half`` of a segment.  With ``c`` the segment's point nearest the car, ``d = |p - c|``,
    ``n = (p - c) / d``, ``e = (cos psi, sin psi)`` and ``e_perp = (-sin psi, cos psi)``::

        b   = d - half - margin          (px; >= 0: clear of the wall and the margin)
        b'  = s n . e
        b'' = s^2 kappa + s (n . e_perp) u     kappa = (1 - (n . e)^2) / d at a wall's end, 0 along its side

    ``"distance"``: the high-order row ``-s (n . e_perp) u <= s^2 kappa + (p1 + p2) b' + p1 p2 b``.
    ``"turning"``: ``B = b - R (1 - |n . e_perp|)`` while approaching (``n . e < 0``), ``B = b``
    otherwise, ``R = s / u_max``: the closest a car turning away at full rate comes.  ``B`` is
    ``C^1`` except head-on and of relative degree 1: with ``sigma = sign(n . e_perp)`` (left on a
    tie), ``B' = s n . e + R sigma ((dn/dt) . e_perp - u n . e)`` while approaching, ``(dn/dt) .
    e_perp = -s (n . e_perp)(n . e) / d`` at a wall's end, 0 along its side.  Along a flat wall the
    full turn away gives ``B' = 0``, so ``B' + p1 B >= 0`` is feasible wherever ``B >= 0`` (tested).
    Each wall gives ``-(coefficient of u in B') u <= (the rest of B') + p1 B``."""
    x, y, psi = float(state[0]), float(state[1]), float(state[2])
    ax, ay = walls[:, 0], walls[:, 1]
    abx, aby = walls[:, 2] - ax, walls[:, 3] - ay
    L2 = abx * abx + aby * aby
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(L2 > 0, ((x - ax) * abx + (y - ay) * aby) / L2, 0.0)
    t = np.clip(t, 0.0, 1.0)
    dx, dy = x - (ax + t * abx), y - (ay + t * aby)
    d = np.maximum(np.hypot(dx, dy), 1e-9)
    nx, ny = dx / d, dy / d
    c, s = math.cos(psi), math.sin(psi)
    ne = nx * c + ny * s  # n . e: < 0 while approaching the wall
    nperp = -nx * s + ny * c  # n . e_perp
    cap = (t <= 0.0) | (t >= 1.0)  # nearest point at a wall's end: n turns as the car moves
    b = d - half - margin
    if barrier == "distance":
        kappa = np.where(cap, (1.0 - ne * ne) / d, 0.0)
        h = speed * speed * kappa + (p1 + p2) * speed * ne + p1 * p2 * b
        return b, (-speed * nperp)[:, None], h
    R = speed / u_max
    approach = ne < 0.0
    sigma = np.where(nperp >= 0.0, 1.0, -1.0)  # the turn that takes the heading away from the wall
    B = np.where(approach, b - R * (1.0 - np.abs(nperp)), b)
    ndot_eperp = np.where(cap, -speed * nperp * ne / d, 0.0)  # (dn/dt) . e_perp
    coef_u = np.where(approach, -R * sigma * ne, 0.0)
    h = speed * ne + np.where(approach, R * sigma * ndot_eperp, 0.0) + p1 * B
    return B, (-coef_u)[:, None], h


class WallQP:
    """``min (u - u_ref)^2  s.t.  G u <= h, |u| <= u_max`` for ``K`` wall rows, on the direct OSQP path
    (set up once, values and bounds updated per step, warm-started) or through qpsolvers
    (``name``: an installed qpsolvers solver, :mod:`rmm_guardians.cbf.backend`)."""

    def __init__(self, K: int, u_max: float, eps: float, name: str | None = None) -> None:
        self.K = K
        self.u_max = u_max
        self.name = name
        if name is not None:
            self._qp = QpsolversQP(np.array([[2.0]]), name, eps, lb=[-u_max], ub=[u_max], polish=False)
            return
        A = sp.csc_matrix(np.ones((K + 1, 1)))  # K wall rows, then the turn-rate box
        self._Ax = np.ones(K + 1)
        self._l = np.r_[np.full(K, -np.inf), -u_max]
        self._u = np.r_[np.zeros(K), u_max]
        self._solver = osqp.OSQP()
        # no polishing: a one-variable problem reaches eps without it, and OSQP writes a line to
        # stderr for every solution with no active row when polishing is on
        self._solver.setup(
            sp.csc_matrix([[2.0]]),
            np.zeros(1),
            A,
            self._l,
            self._u,
            verbose=False,
            eps_abs=eps,
            eps_rel=eps,
            polishing=False,
            warm_starting=True,
            max_iter=4000,
        )

    def solve(self, G, h, u_ref: float = 0.0) -> np.ndarray | None:
        """The solution ``u*`` (shape ``(1,)``) closest to ``u_ref``; ``None`` if infeasible or the
        solver failed."""
        q = np.array([-2.0 * float(u_ref)])
        if self.name is not None:
            self._qp.q[:] = q
            return self._qp.solve(G, h)
        self._Ax[: self.K] = G[:, 0]
        self._u[: self.K] = h
        self._solver.update(q=q, Ax=self._Ax, u=self._u)
        res = self._solver.solve(raise_error=False)
        if res.info.status_val not in (1, 2) or res.x is None or not np.all(np.isfinite(res.x)):
            return None
        return np.asarray(res.x)


class MazeCBFGuardian(PrivilegedGuardian):
    """HOCBF safety filter for the maze car; see the module docstring.

    The QP over the turn rate: minimise ``(u - u_ref)^2`` under the rows of the ``n_walls``
    nearest walls (:func:`wall_rows`) and ``|u| <= u_max`` (from the action space), ``u_ref``
    ``0`` (``reference="hold"``, the default: keep the heading) or the driver's turn rate,
    ``info["nominal_control"]`` (``"nominal"``).  A reference that satisfies every row is the
    solution (no solve).  It takes control, applying ``u*``, when a row is active at the solution
    (``|G_i u* - h_i| <= active_atol``); an infeasible or failed QP turns at full rate the way that
    best satisfies the hardest row (the largest ``h_i - G_i u`` over ``|u| <= u_max``), counted in
    ``stats()["qp_fallbacks"]``.  A pose with NaN applies the env's safe default (the maximum turn
    away from the nearer wall), counted as ``nan_states``.

    Defaults: ``p1 = 1`` /s for the turning barrier (``0.1`` for the distance barrier, whose
    ``p2 = 0.1``); ``margin = 2`` px (about two 0.11-s laps of travel at 10 px/s); ``n_walls = 8``
    (farther walls are more than a corridor away, their rows slack); ``predict_latency``: the
    pose one lap ahead under the control acting during the lap (``hold`` takes 0 for the driver's,
    at most ``u_max lap`` = 0.022 rad of heading error at 0.11 s), ``lap_guess = 0.1`` s before the
    first measured lap; ``eps = 1e-6``, ``solver = "osqp"``, ``active_atol = 1e-3``."""

    name = "cbf"
    #: as a part of its method (rmm_guardians.parts): what it models, its controls, its settings field
    serves, controls, option = "the maze car", CONTROLS, "maze"

    def __init__(
        self,
        barrier: str = "turning",
        p1: float | None = None,
        p2: float = 0.1,
        margin: float = 2.0,
        n_walls: int = 8,
        active_atol: float = 1e-3,
        predict_latency: bool = True,
        lap_guess: float = 0.1,
        eps: float = 1e-6,
        solver: str = "osqp",
        reference: str = "hold",
    ) -> None:
        super().__init__()
        if reference not in MAZE_REFERENCES:
            raise ValueError(
                f"reference must be one of {MAZE_REFERENCES} (filter the driver's "
                f"info['nominal_control'], or hold the heading), got {reference!r}"
            )
        self.reference = reference
        if barrier not in BARRIERS:
            raise ValueError(f"barrier must be one of {BARRIERS}, got {barrier!r}")
        self.barrier = barrier
        p1 = (1.0 if barrier == "turning" else 0.1) if p1 is None else p1
        self.p1 = finite("p1 (class-K gain)", p1, 0.0, lo_open=True)
        self.p2 = finite("p2 (class-K gain)", p2, 0.0, lo_open=True)
        self.margin = finite("margin", margin, 0.0)
        self.n_walls = integer("n_walls", n_walls, 1)
        self.active_atol = finite("active_atol", active_atol, 0.0)
        self.predict_latency = bool(predict_latency)
        self.lap_guess = finite("lap_guess", lap_guess, 0.0, lo_open=True)
        self.eps = finite("eps", eps, 0.0, lo_open=True)
        self._solver_name = parse_solver(solver)
        self.solver = solver
        self._counts = self._zero()
        self._barrier_min = math.nan  # the last decision's smallest barrier value (signals())

    @staticmethod
    def _zero() -> dict:
        return {"qp_fallbacks": 0, "nan_states": 0, "qp_solves": 0}

    def check_spaces(self, observation_space, action_space) -> None:
        maze_car_only(self, action_space)

    def reset(self, **kwargs) -> None:
        super().reset(**kwargs)
        self.check_spaces(self.observation_space, self.action_space)
        space = self.action_space
        assert space is not None  # check_spaces refused anything but the maze car's GuardianActionSpace
        assert self._privileged is not None  # Guardian.reset refuses a privileged guardian without it
        priv = self._privileged()
        if "speed" not in priv:
            raise ValueError(
                f"guardian {self.name!r} (maze) needs the car's speed in the env's privileged data "
                f"(keys: {sorted(priv)})"
            )
        self.speed = finite("privileged speed", priv["speed"], 0.0, lo_open=True)
        maze = priv["maze"]
        self.walls = np.asarray(maze.walls, float)
        if self.walls.shape[0] == 0:
            raise ValueError(f"guardian {self.name!r} (maze) needs a maze with walls, got none")
        self.half = float(maze.half)
        self.u_max = float(space.control_high[0])
        self.K = min(self.n_walls, self.walls.shape[0])
        self._qp = WallQP(self.K, self.u_max, self.eps, self._solver_name)
        self._safe = space.safe_default.policy(space, self.rng) if space.safe_default is not None else None
        self._counts = self._zero()
        self._barrier_min = math.nan  # the last decision's smallest barrier value (signals())
        # the guardian's turn rate acting during the coming lap; None: the driver's
        self._pending: float | None = None
        self.start_laps(self.lap_guess, since=priv.get("sim_time", 0.0))

    # ------------------------------------------------------------------ the maths
    def rows(self, state):
        """``(b, G, h)`` of the ``n_walls`` walls nearest ``state`` (smallest ``b`` first)."""
        b, G, h = wall_rows(
            state, self.speed, self.walls, self.half, self.margin, self.p1, self.p2, self.barrier, self.u_max
        )
        idx = np.argsort(b, kind="stable")[
            : self.K
        ]  # stable: ties keep wall order on every CPU (argpartition's do not)
        return b[idx], G[idx], h[idx]

    def solve(self, state, u_ref: float = 0.0):
        """The QP's ``u*`` closest to ``u_ref`` at ``state`` (``None`` if it failed) and its rows ``(G, h)``."""
        _, G, h = self.rows(state)
        self._counts["qp_solves"] += 1
        return self._qp.solve(G, h, u_ref), G, h

    def predict(self, state, u: float, lap: float) -> np.ndarray:
        """The exact pose after ``lap`` seconds of turn rate ``u`` (heading wrapped)."""
        x, y, psi = (float(v) for v in state[:3])
        # the chord of the arc in its half-angle form, (s lap) sinc(u lap / 2) along the mean
        # heading: the same value as (s / u)(sin(psi + u lap) - sin(psi)), ..., without that
        # form's cancellation at small turn rates (a relative error of eps / (u lap))
        half = 0.5 * u * lap
        chord = self.speed * lap * (math.sin(half) / half if half != 0.0 else 1.0)
        x, y = x + chord * math.cos(psi + half), y + chord * math.sin(psi + half)
        psi += u * lap
        return np.array([x, y, (psi + math.pi) % (2 * math.pi) - math.pi])

    # ------------------------------------------------------------------ the decision
    def _emit(self, u: float):
        u = min(max(float(u), -self.u_max), self.u_max)
        self._pending = u
        assert self.action_space is not None  # checked at reset (maze_car_only)
        return self.action_space.active(np.array([u]))

    def nominal(self, info) -> float:
        """The driver's turn rate this step, ``info["nominal_control"]`` (``reference="nominal"``;
        a ``ValueError`` naming the key when the env gives none), or 0 (``"hold"``)."""
        if self.reference != "nominal":
            return 0.0
        u = None if not isinstance(info, dict) else info.get("nominal_control")
        if u is None:
            raise ValueError(
                f"guardian {self.name!r} (maze) filters the driver's control, info['nominal_control'], "
                f"but the step's info has none (keys: {sorted(info) if isinstance(info, dict) else info!r}); "
                "use reference='hold' for an env without it"
            )
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.shape != (1,) or not math.isfinite(u[0]):
            raise ValueError(f"info['nominal_control'] must be one finite turn rate, got {info['nominal_control']!r}")
        return float(u[0])

    def act(self, observation, info=None):
        u_nom = self.nominal(info)
        priv = self._privileged()
        state = np.asarray(priv["state"], float)
        if not self.finite_state(state):
            u = self._safe(observation)[0] if self._safe is not None else self.u_max
            return self._emit(u)
        if self.predict_latency:
            self.measure_lap(priv)
            during = self._pending if self._pending is not None else u_nom  # the driver's is the nominal
            state = self.predict(state, during, self._measured_lap)
        return self.decide(state, u_nom)

    def decide(self, state, u_ref: float = 0.0):
        """The decision for the pose the action will act from (already predicted): the turn rate
        closest to ``u_ref`` (the driver's, or 0) that the barriers allow."""
        b, G, h = self.rows(state)
        self._barrier_min = float(b[0]) if b.size else math.nan
        if np.all(G[:, 0] * u_ref <= h + self.eps) and abs(u_ref) <= self.u_max:
            # the reference satisfies every row: it is the solution, no solve
            z: np.ndarray | None = np.array([u_ref])
        else:
            self._counts["qp_solves"] += 1
            z = self._qp.solve(G, h, u_ref)
        if z is None:
            self._counts["qp_fallbacks"] += 1
            slack = h + np.abs(G[:, 0]) * self.u_max  # each row's best slack over the box
            g = G[int(np.argmin(slack)), 0]
            return self._emit(-self.u_max if g > 0 else self.u_max)
        if np.any(np.abs(h - G[:, 0] * z[0]) <= self.active_atol):
            return self._emit(z[0])
        self._pending = None
        assert self.action_space is not None  # checked at reset (maze_car_only)
        return self.action_space.inactive()

    def stats(self) -> dict:
        return dict(self._counts)

    def signals(self) -> dict[str, float]:
        """``barrier_min``: the smallest barrier value of the last decision's rows (nearest shape
        first; ``nan`` before one); ``qp_fallbacks``: the episode's infeasible QPs so far."""
        return {"barrier_min": self._barrier_min, "qp_fallbacks": float(self._counts["qp_fallbacks"])}

    def alarm(self) -> tuple[float, float]:
        """``(-barrier_min, 0)``: up when the last decision's smallest barrier value is below 0."""
        return -float(self._barrier_min), 0.0
