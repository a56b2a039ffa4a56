"""What the methods' parts for each built-in system require of an env's action space.

The requirements ``cbf`` and ``hj`` share for one system: :func:`dubins4d_only` (their own
classes, the Dubins4D car among circles), :func:`maze_car_only` and :func:`quadrotor_only`
(their maze car and quadrotor parts, :mod:`rmm_guardians.parts`).  Each checks the dynamics and
controls with :func:`rmm_guardians.dispatch.require_dynamics`, the controls read from the
system's dynamics, then what the part's model needs (``ValueError`` naming the guardian and why).
"""

from __future__ import annotations

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.systems.dubins4d import dynamics as dubins4d
from rmm_envs.systems.maze import dynamics as dubins3d
from rmm_envs.systems.quadrotor import control as quadrotor_control
from rmm_guardians.dispatch import require_dynamics

__all__ = ["dubins4d_only", "maze_car_only", "quadrotor_only"]


def dubins4d_only(guardian, action_space, also: tuple = ()) -> None:
    """Refuse an env that is not a Dubins4D one among circles (``ValueError`` naming the guardian
    and why): ``cbf`` and ``hj`` model the Dubins4D car among circles, so an action space that
    states other obstacle shapes (a map with polygons or walls) is refused too.  ``also``: the
    parts of the other dynamics the guardian serves (their ``serves`` and ``controls``), said in the
    message."""
    served = "Dubins4D envs" + "".join(f" and {p.serves} (controls {tuple(p.controls)})" for p in also)
    require_dynamics(
        guardian,
        action_space,
        dubins4d.DYNAMICS_NAME,
        dubins4d.CONTROLS,
        f"applies to {served}{'' if also else ' only'}: it models the Dubins4D car among circular obstacles",
    )
    shapes = action_space.obstacle_shapes
    other = [s for s in (shapes or ()) if s != "circle"]
    if other:
        raise ValueError(
            f"guardian {guardian.name!r} models circular obstacles only, and this env's world also has "
            f"{', '.join(other)} obstacles (a map with shapes {list(shapes)}); use a map of circles only, "
            "or a guardian that needs no obstacle geometry (lrmm, brakes)"
        )


def maze_car_only(guardian, action_space) -> GuardianActionSpace:
    """Refuse an env that is not the maze car's, or whose turn-rate bound is not ``[-b, b]`` with
    ``b > 0`` (``ValueError`` naming the guardian and why); the checked action space otherwise."""
    space = require_dynamics(
        guardian,
        action_space,
        dubins3d.DYNAMICS_NAME,
        dubins3d.CONTROLS,
        "(maze) models the constant-speed maze car among walls",
    )
    lo, hi = float(space.control_low[0]), float(space.control_high[0])
    if not (hi > 0 and lo == -hi):
        raise ValueError(
            f"guardian {guardian.name!r} (maze) needs a turn-rate bound symmetric about 0 and wider than a "
            f"point ([-b, b] with b > 0), got [{lo}, {hi}]"
        )
    return space


def quadrotor_only(guardian, action_space) -> GuardianActionSpace:
    """Refuse an env that is not the quadrotor's, or whose command box does not contain the zero
    command (hover) or is a single point on some axis (``low <= 0 <= high`` and ``low < high`` on
    each; ``ValueError`` naming the guardian and why); the checked action space otherwise."""
    space = require_dynamics(
        guardian,
        action_space,
        quadrotor_control.DYNAMICS_NAME,
        quadrotor_control.CONTROLS,
        "(quadrotor) models the quadrotor's velocity command in a room",
    )
    lo, hi = np.asarray(space.control_low, float), np.asarray(space.control_high, float)
    if not (np.all(lo <= 0.0) and np.all(hi >= 0.0) and np.all(lo < hi)):
        raise ValueError(
            f"guardian {guardian.name!r} (quadrotor) needs a command box that contains the zero command "
            f"(hover) and is wider than a point in each of {space.controls} (low <= 0 <= high, low < high), "
            f"got low {lo.tolist()} and high {hi.tolist()}"
        )
    return space
