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

import numpy as np

from rmm_envs.systems.dubins4d.circles import contact_params_each
from rmm_envs.systems.dubins4d.driver import CLFDriver
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, wrap_angle

__all__ = ["advance", "nominal_controls"]


def nominal_controls(driver: CLFDriver, states: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """The driver's controls ``(N, 2)`` at ``states`` ``(N, 4)`` toward each world's goal (the
    last row of ``circles`` ``(N, K + 1, 3)``)."""
    return driver.controls(states, circles[:, -1, :2])


def advance(
    dynamics: Dubins4D,
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
    paths = dynamics.states_at(states, u, times, compiled=True)
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
