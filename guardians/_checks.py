"""Argument checks shared by the guardians' constructors: a bad value is refused with a
message that names the argument, the value and what was expected."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MazeDelegation", "QuadrotorDelegation", "dubins4d_only", "finite", "integer", "is_maze_space", "is_quadrotor_space",
           "maze_car_only", "number_pair", "quadrotor_only"]


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


def dubins4d_only(guardian, action_space, maze: bool = False, quadrotor: bool = False) -> None:
    """Refuse an env that is not a Dubins4D one (``ValueError`` naming the guardian and why): the
    privileged guardians (``cbf``, ``hj``) model the Dubins4D car among circles, so they need its
    two controls (turn rate, acceleration) and circular obstacles in its privileged data: an env
    whose action space states other obstacle shapes (``obstacle_shapes``, a map with polygons or
    walls) is refused too.  ``maze``: the guardian also serves the maze car (its own check ran
    first), said in the message; so is ``quadrotor``."""
    from rmm_envs.systems.dubins4d import CONTROLS

    name = guardian.name
    controls = guardian.require_action_space(space=action_space).controls
    if tuple(controls) != CONTROLS:
        systems = "Dubins4D envs" + (" and the maze car (controls ('turnrate_ctrl',))" if maze else "") \
            + (f" and the quadrotor (controls {_quadrotor_controls()})" if quadrotor else "") + ("" if maze or quadrotor else " only")
        raise ValueError(f"guardian {name!r} applies to {systems}: it models the Dubins4D car (controls "
                         f"{CONTROLS}) among circular obstacles, and this env's controls are {controls}")
    shapes = getattr(action_space, "obstacle_shapes", None)
    other = [s for s in (shapes or ()) if s != "circle"]
    if other:
        raise ValueError(f"guardian {name!r} models circular obstacles only, and this env's world also has "
                         f"{', '.join(other)} obstacles (a map with shapes {list(shapes)}); use a map of circles only, "
                         "or a guardian that needs no obstacle geometry (lrmm, brakes)")


def _maze_controls() -> tuple[str, ...]:
    from rmm_envs.systems.dubins3d import CONTROLS

    return tuple(CONTROLS)


def is_maze_space(action_space) -> bool:
    """Whether ``action_space`` is the maze car's: a guardian action space with its one control
    (the turn rate, :data:`rmm_envs.envs.dubins3d_maze_parallel.CONTROLS`)."""
    return tuple(getattr(action_space, "controls", ())) == _maze_controls()


def maze_car_only(guardian, action_space):
    """Refuse an env that is not the maze car's, or whose turn-rate bound is not symmetric about 0
    (``ValueError`` naming the guardian and why); the checked action space otherwise.  The
    privileged maze guardians (``cbf``, ``hj`` on ``Dubins3DMazeParallel-v0``) need both."""
    space = guardian.require_action_space(space=action_space)
    if not is_maze_space(space):
        raise ValueError(f"guardian {guardian.name!r} (maze) models the constant-speed maze car (controls "
                         f"{_maze_controls()}) among walls; this env's controls are {space.controls}")
    lo, hi = float(space.control_low[0]), float(space.control_high[0])
    if not (hi > 0 and lo == -hi):
        raise ValueError(f"guardian {guardian.name!r} (maze) needs a turn-rate bound symmetric about 0, got [{lo}, {hi}]")
    return space


class MazeDelegation:
    """One guardian name for the Dubins4D car and the maze car: a mixin for a Dubins4D guardian
    class whose maze counterpart is ``maze_class``.  On an env whose action space is the maze
    car's (and when the guardian was built to serve the maze, ``self._maze_args`` not ``None``),
    the checks and the episode go to one delegate of ``maze_class``, built on the first maze env
    with ``self._maze_args`` and the guardian's name; elsewhere the Dubins4D checks apply."""

    maze_class: type
    _maze_args: dict | None = None
    _delegate = None  # the maze car's guardian, built on the first maze env

    def _maze_guardian(self, action_space):
        """The delegate when ``action_space`` is the maze car's (and this guardian serves the
        maze), else ``None``."""
        if self._maze_args is None or not is_maze_space(action_space):
            return None
        if self._delegate is None:
            self._delegate = self.maze_class(**self._maze_args)
            self._delegate.name = self.name
        return self._delegate

    def check_spaces(self, observation_space, action_space) -> None:
        maze = self._maze_guardian(action_space)
        if maze is not None:
            return maze.check_spaces(observation_space, action_space)
        dubins4d_only(self, action_space, maze=self._maze_args is not None,
                      quadrotor=getattr(self, "_quadrotor_args", None) is not None)


def _quadrotor_controls() -> tuple[str, ...]:
    from rmm_envs.systems.quadrotor_control import CONTROLS

    return tuple(CONTROLS)


def is_quadrotor_space(action_space) -> bool:
    """Whether ``action_space`` is the quadrotor's: a guardian action space with its four
    commands (:data:`rmm_envs.envs.quadrotor_room_parallel.CONTROLS`)."""
    return tuple(getattr(action_space, "controls", ())) == _quadrotor_controls()


def quadrotor_only(guardian, action_space):
    """Refuse an env that is not the quadrotor's, or whose command box does not contain the zero
    command (hover; ``ValueError`` naming the guardian and why); the checked action space otherwise."""
    space = guardian.require_action_space(space=action_space)
    if not is_quadrotor_space(space):
        raise ValueError(f"guardian {guardian.name!r} (quadrotor) models the quadrotor's velocity command (controls "
                         f"{_quadrotor_controls()}) in a room; this env's controls are {space.controls}")
    lo, hi = np.asarray(space.control_low, float), np.asarray(space.control_high, float)
    if not (np.all(lo <= 0.0) and np.all(hi >= 0.0) and np.all(lo < hi)):
        raise ValueError(f"guardian {guardian.name!r} (quadrotor) needs a command box that contains the zero command "
                         f"(hover) in each of {space.controls}, got low {lo.tolist()} and high {hi.tolist()}")
    return space


class QuadrotorDelegation:
    """One guardian name for the quadrotor too: a mixin (before :class:`MazeDelegation` or the
    guardian class) whose quadrotor counterpart is ``quadrotor_class``.  On an env whose action
    space is the quadrotor's (and when the guardian serves it, ``self._quadrotor_args`` not
    ``None``), the checks go to one delegate of ``quadrotor_class``, built on the first such env
    with those arguments and the guardian's name; elsewhere the next class's checks apply."""

    quadrotor_class: type
    _quadrotor_args: dict | None = None
    _quadrotor_delegate = None

    def _quadrotor_guardian(self, action_space):
        """The delegate when ``action_space`` is the quadrotor's (and this guardian serves it),
        else ``None``."""
        if self._quadrotor_args is None or not is_quadrotor_space(action_space):
            return None
        if self._quadrotor_delegate is None:
            self._quadrotor_delegate = self.quadrotor_class(**self._quadrotor_args)
            self._quadrotor_delegate.name = self.name
        return self._quadrotor_delegate

    def check_spaces(self, observation_space, action_space) -> None:
        quad = self._quadrotor_guardian(action_space)
        if quad is not None:
            return quad.check_spaces(observation_space, action_space)
        return super().check_spaces(observation_space, action_space)
