"""Which guardian serves which dynamics: dispatch on the kind an env's action space states.

An env's :class:`rmm_envs.autonomy.GuardianActionSpace` carries its system's contract
(``space.contract``: the dynamics' kind, control names, bounds, safe default).  This module offers:

* :func:`require_dynamics`: a guardian that models one kind of dynamics refuses a space of another
  (``ValueError`` naming the guardian, the kind it models and the env's); :func:`dubins4d_only`,
  :func:`maze_car_only` and :func:`quadrotor_only` add each one's own requirements;
* :class:`DynamicsDispatch`: one guardian name (``cbf``, ``hj``) for several kinds of dynamics:
  the space's kind picks the class that models it, built once with its arguments.

Third-party envs state kind ``"generic"``; only guardians that model no dynamics serve them.
"""

from __future__ import annotations

import numpy as np

from rmm_envs.autonomy import GuardianActionSpace
from rmm_envs.dynamics import dubins3d, dubins4d, quadrotor_control

__all__ = ["DYNAMICS", "DynamicsDispatch", "dubins4d_only", "maze_car_only", "quadrotor_only", "require_dynamics"]

#: The dynamics built-in guardians model: kind -> (its controls, how messages name it).
DYNAMICS = {
    dubins4d.KIND: (dubins4d.CONTROLS, "Dubins4D envs"),
    dubins3d.KIND: (dubins3d.CONTROLS, "the maze car"),
    quadrotor_control.KIND: (quadrotor_control.CONTROLS, "the quadrotor"),
}


def require_dynamics(guardian, action_space, kind: str, model: str) -> GuardianActionSpace:
    """``action_space`` checked to be a guardian action space of dynamics ``kind`` with those
    dynamics' controls; ``model`` (what the guardian models, in words) opens the message of the
    ``ValueError`` otherwise."""
    space = guardian.require_action_space(space=action_space)
    controls = tuple(DYNAMICS[kind][0])
    if space.kind != kind:
        raise ValueError(
            f"guardian {guardian.name!r} {model} (dynamics {kind!r}, controls {controls}); this env's dynamics "
            f"are {space.kind!r} and its controls are {space.controls}"
        )
    if tuple(space.controls) != controls:
        raise ValueError(
            f"guardian {guardian.name!r}: this env states dynamics {kind!r}, whose controls are {controls}, "
            f"but its action space's controls are {space.controls}"
        )
    return space


def dubins4d_only(guardian, action_space, also: tuple[str, ...] = ()) -> None:
    """Refuse an env that is not a Dubins4D one among circles (``ValueError`` naming the guardian
    and why): ``cbf`` and ``hj`` model the Dubins4D car among circles, so an action space that
    states other obstacle shapes (a map with polygons or walls) is refused too.  ``also``: the
    other kinds the guardian serves (through :class:`DynamicsDispatch`), said in the message."""
    served = "Dubins4D envs" + "".join(f" and {DYNAMICS[k][1]} (controls {tuple(DYNAMICS[k][0])})" for k in also)
    require_dynamics(
        guardian,
        action_space,
        dubins4d.KIND,
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
        guardian, action_space, dubins3d.KIND, "(maze) models the constant-speed maze car among walls"
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
        guardian, action_space, quadrotor_control.KIND, "(quadrotor) models the quadrotor's velocity command in a room"
    )
    lo, hi = np.asarray(space.control_low, float), np.asarray(space.control_high, float)
    if not (np.all(lo <= 0.0) and np.all(hi >= 0.0) and np.all(lo < hi)):
        raise ValueError(
            f"guardian {guardian.name!r} (quadrotor) needs a command box that contains the zero command "
            f"(hover) and is wider than a point in each of {space.controls} (low <= 0 <= high, low < high), "
            f"got low {lo.tolist()} and high {hi.tolist()}"
        )
    return space


class DynamicsDispatch:
    """One guardian name for several systems: a mixin before :class:`rmm_guardians.base.Guardian`.

    The class models the Dubins4D car itself; ``others`` maps each other kind it may serve to the
    class that models it, and ``self._dynamics_args`` (set by the constructor) maps a kind to that
    class's arguments (absent or ``None``: this guardian refuses that system's envs).  On a
    space of such a kind, :meth:`check_spaces` and the episode go to one delegate, built on the
    first such env with those arguments and the guardian's name; :attr:`delegate` is the one
    serving the current episode (``None``: the class's own)."""

    others: dict = {}
    _dynamics_args: dict = {}
    delegate = None

    def _delegate_for(self, action_space):
        """The delegate for ``action_space``'s kind, or ``None`` when the class serves it itself
        (or refuses it)."""
        kind = getattr(action_space, "kind", None)
        if kind not in self.others or self._dynamics_args.get(kind) is None:
            return None
        built = self.__dict__.setdefault("_delegates", {})
        if kind not in built:
            built[kind] = self.others[kind](**self._dynamics_args[kind])
            built[kind].name = self.name
        return built[kind]

    def served(self) -> tuple[str, ...]:
        """The other kinds this guardian serves, in the order of :data:`DYNAMICS`."""
        return tuple(k for k in DYNAMICS if k in self.others and self._dynamics_args.get(k) is not None)

    def check_spaces(self, observation_space, action_space) -> None:
        other = self._delegate_for(action_space)
        if other is not None:
            return other.check_spaces(observation_space, action_space)
        dubins4d_only(self, action_space, also=self.served())

    def _dispatch_reset(self, kwargs: dict) -> bool:
        """Pick the episode's delegate from ``kwargs["action_space"]`` and reset it; whether one
        serves the episode (the caller's own reset runs otherwise)."""
        self.delegate = self._delegate_for(kwargs.get("action_space"))
        if self.delegate is None:
            return False
        self.delegate.reset(**kwargs)
        return True


def delegate_arguments(cls, what: str, given, shared: dict) -> dict | None:
    """The arguments of the ``what`` system's guardian ``cls``: ``given`` (a dict of its
    arguments; ``False`` refuses that system's envs) over the arguments all systems share;
    checked by building one (a bad argument fails at construction, naming it)."""
    if given is False:
        return None
    if given is not None and not isinstance(given, dict):
        raise ValueError(
            f"{what} must be a dict of {cls.__module__}.{cls.__name__} arguments (or False), got {given!r}"
        )
    args = shared | dict(given or {})
    cls(**args)
    return args
