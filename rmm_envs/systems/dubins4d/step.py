"""One Dubins4D environment step for ``N`` worlds at once: driver, exact path, contacts.

The driver's control at each world's state (:func:`nominal_controls`) is computed once, when
the state is observed, and handed to :func:`advance`: the same numbers are the env's
``info["nominal_control"]`` and what the driver applies when the guardian stays inactive.

Shared by :class:`rmm_envs.systems.dubins4d.env.Dubins4DGuardedEnv` (``N = 1``) and
:class:`rmm_envs.systems.dubins4d.vector.Dubins4DCirclesVectorEnv` (``N`` sub-environments), so
both run the very same floating-point operations: every stage is a compiled loop over the
worlds (the driver's closed-form QP, the exact zero-order-hold path, the contact parameters),
whose result for one world does not depend on the others in the batch.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rmm_envs.systems.dubins4d.circles import contact_params_each
from rmm_envs.systems.dubins4d.driver import CLFDriver
from rmm_envs.systems.dubins4d.dynamics import (
    SERIES_COEFFICIENTS,
    Dubins4D,
    _clamped_start,
    _state_at_1,
    njit,
    wrap_angle,
)

__all__ = ["advance", "nominal_controls", "states_at_rows"]


def _states_at_rows_loop(states, controls, times, lo, hi, coef, out):
    """The compiled ``states_at`` loop with bounds of its own per row (``lo``/``hi``: ``(N, 3)``,
    each row a plant's (v, u1, u2) bounds): row ``n`` is the same operations as that plant's
    ``states_at`` of the one state."""
    t_end = 0.0
    for k in range(times.shape[0]):
        t_end = max(t_end, times[k])
    for n in range(states.shape[0]):
        v0, w, a, sat, t_sat = _clamped_start(states[n, 3], controls[n, 0], controls[n, 1], t_end, lo[n], hi[n])
        for k in range(times.shape[0]):
            out[n, k, 0], out[n, k, 1], out[n, k, 2], out[n, k, 3] = _state_at_1(
                states[n, 0], states[n, 1], states[n, 2], v0, w, a, times[k], sat, t_sat, lo[n], hi[n], coef
            )
    return out


_states_at_rows = _states_at_rows_loop if njit is None else njit(cache=True)(_states_at_rows_loop)


def states_at_rows(plants, states: np.ndarray, controls: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``(N, T, 4)``: row ``n`` is ``plants[n].states_at(states[n:n + 1], controls[n:n + 1],
    times, compiled=True)[0]``, every row in one compiled loop (plants that differ in their
    bounds, as a model mismatch draws them)."""
    lo = np.ascontiguousarray([p._lo for p in plants], dtype=float)
    hi = np.ascontiguousarray([p._hi for p in plants], dtype=float)
    out = np.empty((states.shape[0], len(times), 4))
    return _states_at_rows(
        np.ascontiguousarray(states, dtype=float),
        np.ascontiguousarray(controls, dtype=float),
        np.asarray(times, dtype=float),
        lo,
        hi,
        SERIES_COEFFICIENTS,
        out,
    )


def nominal_controls(driver: CLFDriver, states: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """The driver's controls ``(N, 2)`` at ``states`` ``(N, 4)`` toward each world's goal (the
    last row of ``circles`` ``(N, K + 1, 3)``)."""
    return driver.controls(states, circles[:, -1, :2])


def advance(
    dynamics: Dubins4D | Sequence[Dubins4D],
    nominal: np.ndarray,
    states: np.ndarray,
    circles: np.ndarray,
    active: np.ndarray,
    controls: np.ndarray,
    times: np.ndarray,
    obstacle_contact=None,
    drift: np.ndarray | None = None,
):
    """Advance ``N`` worlds by one held control each.

    Args:
        dynamics: the plant, or one plant per world (a model mismatch's, :func:`states_at_rows`).
        nominal: ``(N, 2)`` the driver's controls at ``states`` (:func:`nominal_controls`).
        states: ``(N, 4)`` states.
        circles: ``(N, K + 1, 3)``: each world's obstacles, then its goal (last).
        active: ``(N,)`` bool: the guardian's control applies; otherwise the driver's.
        controls: ``(N, 2)`` the guardian's controls (already validated and clipped); rows
            where ``active`` is false are ignored.
        times: ``(S,)`` path times, ``0 ... duration``.
        obstacle_contact: ``None`` (the circles before the goal are the obstacles), or a
            function ``paths (N, S, 4) -> (N,)`` giving the first obstacle contact parameters
            of another world (then ``circles`` holds the goal only): the map env's hook.
        drift: ``None``, or ``(N, 4)`` rates added to the state's over the whole step (a
            disturbance on the position rates: ``x`` and ``y`` move by ``drift * t`` on top of the
            car's own motion, exactly, as heading and speed do not depend on position).

    Returns ``(next_states, applied_controls, hit_obstacle, hit_goal)``: the path's end with the
    heading wrapped to ``[-pi, pi)``, ``(N, 2)``, and the first contact parameters ``(N,)``
    with any obstacle and with the goal (``inf`` where none).
    """
    u = np.where(active[:, None], np.asarray(controls, dtype=float), nominal)
    if isinstance(dynamics, Dubins4D):
        paths = dynamics.states_at(states, u, times, compiled=True)
    else:
        paths = states_at_rows(dynamics, states, u, times)
    if drift is not None:
        paths = paths + np.asarray(drift, float)[:, None, :] * np.asarray(times, float)[None, :, None]
    cp = contact_params_each(paths, circles)
    hit_goal = cp[:, -1]
    if obstacle_contact is not None:
        hit_obst = obstacle_contact(paths)
    else:
        hit_obst = cp[:, :-1].min(axis=1) if cp.shape[1] > 1 else np.full(cp.shape[0], np.inf)
    nxt = paths[:, -1].copy()
    nxt[:, 2] = wrap_angle(nxt[:, 2])
    return nxt, u, hit_obst, hit_goal
