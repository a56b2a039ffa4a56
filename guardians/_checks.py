"""Argument checks shared by the guardians' constructors: a bad value is refused with a
message that names the argument, the value and what was expected."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["dubins4d_only", "finite", "integer", "number_pair"]


def finite(name: str, value, lo: float | None = None, lo_open: bool = False) -> float:
    """``value`` as a float, refused (naming it) unless finite and, if ``lo`` is given, at least
    ``lo`` (above it with ``lo_open``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(x) or (lo is not None and (x <= lo if lo_open else x < lo)):
        bound = "" if lo is None else f" {'>' if lo_open else '>='} {lo}"
        raise ValueError(f"{name} must be a finite number{bound}, got {value!r}")
    return x


def integer(name: str, value, lo: int, what: str = "") -> int:
    """``value`` as an int, refused (naming it) unless an integer (not a bool) ``>= lo``;
    ``what`` explains the argument in the message."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo:
        raise ValueError(f"{name} must be an integer >= {lo}{f' ({what})' if what else ''}, got {value!r}")
    return int(value)


def number_pair(name: str, pair) -> tuple[float, float]:
    """``(min, max)`` as floats, refused (naming it) unless both finite with ``min < max``."""
    try:
        lo, hi = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (min, max) pair of numbers, got {pair!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or not lo < hi:
        raise ValueError(f"{name} must be a finite (min, max) with min < max, got {pair!r}")
    return lo, hi


def dubins4d_only(guardian, action_space, maze: bool = False) -> None:
    """Refuse an env that is not a Dubins4D one (``ValueError`` naming the guardian and why): the
    privileged guardians (``cbf``, ``hj``) model the Dubins4D car among circles, so they need its
    two controls (turn rate, acceleration) and circular obstacles in its privileged data: an env
    whose action space states other obstacle shapes (``obstacle_shapes``, a map with polygons or
    walls) is refused too.  ``maze``: the guardian also serves the maze car (its own check ran
    first), said in the message."""
    from rmm_envs.envs.dubins4d import CONTROLS

    name = guardian.name
    controls = guardian.require_action_space(space=action_space).controls
    if tuple(controls) != CONTROLS:
        systems = ("Dubins4D envs and the maze car (controls ('turnrate_ctrl',))" if maze else "Dubins4D envs only")
        raise ValueError(f"guardian {name!r} applies to {systems}: it models the Dubins4D car (controls "
                         f"{CONTROLS}) among circular obstacles, and this env's controls are {controls}")
    shapes = getattr(action_space, "obstacle_shapes", None)
    other = [s for s in (shapes or ()) if s != "circle"]
    if other:
        raise ValueError(f"guardian {name!r} models circular obstacles only, and this env's world also has "
                         f"{', '.join(other)} obstacles (a map with shapes {list(shapes)}); use a map of circles only, "
                         "or a guardian that needs no obstacle geometry (lrmm, brakes)")
