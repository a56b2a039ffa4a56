"""Which guardian serves which dynamics: dispatch on the dynamics an env's action space states.

An env's :class:`rmm_envs.autonomy.GuardianActionSpace` carries its system's contract
(``space.contract``: the dynamics' name, control names, bounds, safe default).  This module offers:

* :func:`require_dynamics`: a guardian that models one dynamics refuses a space of another
  (``ValueError`` naming the guardian, the dynamics it models and the env's); each system's
  further requirements are in :mod:`rmm_guardians.system_checks`;
* :class:`DynamicsDispatch`: one guardian name (``cbf``, ``hj``) for several dynamics: the
  space's dynamics name picks the method's part that models it (:mod:`rmm_guardians.parts`),
  built once with its arguments.

Third-party envs state the dynamics ``"generic"``; only guardians that model no dynamics serve them.
"""

from __future__ import annotations

from collections.abc import Callable

from rmm_envs.autonomy import GuardianActionSpace
from rmm_guardians.parts import parts_of

__all__ = ["DynamicsDispatch", "delegate_arguments", "require_dynamics"]


def require_dynamics(guardian, action_space, dynamics_name: str, controls, model: str) -> GuardianActionSpace:
    """``action_space`` checked to be a guardian action space of the dynamics ``dynamics_name`` whose controls
    are ``controls`` (those dynamics' own, read from their module by the caller); ``model`` (what
    the guardian models, in words) opens the message of the ``ValueError`` otherwise."""
    space = guardian.require_action_space(space=action_space)
    controls = tuple(controls)
    if space.dynamics_name != dynamics_name:
        raise ValueError(
            f"guardian {guardian.name!r} {model} (dynamics {dynamics_name!r}, controls {controls}); this env's "
            f"dynamics are {space.dynamics_name!r} and its controls are {space.controls}"
        )
    if tuple(space.controls) != controls:
        raise ValueError(
            f"guardian {guardian.name!r}: this env states dynamics {dynamics_name!r}, whose controls are {controls}, "
            f"but its action space's controls are {space.controls}"
        )
    return space


class DynamicsDispatch:
    """One guardian name for several systems: a mixin before :class:`rmm_guardians.base.Guardian`.

    The class models one dynamics itself, checked by :attr:`own_check`
    (``own_check(guardian, action_space, also=parts)``, ``parts`` the classes of the other dynamics
    it serves, for the refusal to list).  The other dynamics are its :attr:`method`'s parts
    (:func:`rmm_guardians.parts.parts_of`), read by :meth:`_init_parts` in the constructor with
    each one's arguments (``None``: this guardian refuses that system's envs).  On a space of such
    dynamics, :meth:`check_spaces` and the episode go to one delegate, built on the first such env
    with those arguments and the guardian's name; :attr:`delegate` is the one serving the current
    episode (``None``: the class's own)."""

    method: str = ""  #: the method whose parts serve the other dynamics (rmm_guardians.parts)
    own_check: Callable
    _parts: dict = {}
    _dynamics_args: dict = {}
    delegate = None

    def _init_parts(self, settings, shared: dict) -> None:
        """The method's parts and each one's arguments: ``settings``' field named by the part's
        ``option`` over ``shared`` (:func:`delegate_arguments`; ``shared`` alone when the settings
        have no such field)."""
        self._parts = parts_of(self.method)
        self._dynamics_args = {}
        for name, part in self._parts.items():
            option = getattr(part, "option", None)
            given = getattr(settings, option, None) if option else None
            self._dynamics_args[name] = delegate_arguments(part, option or name, given, shared)

    def _delegate_for(self, action_space):
        """The delegate for ``action_space``'s dynamics, or ``None`` when the class serves them itself
        (or refuses them)."""
        name = getattr(action_space, "dynamics_name", None)
        if name not in self._parts or self._dynamics_args.get(name) is None:
            return None
        built = self.__dict__.setdefault("_delegates", {})
        if name not in built:
            built[name] = self._parts[name](**self._dynamics_args[name])
            built[name].name = self.name
        return built[name]

    def served(self) -> tuple[str, ...]:
        """The names of the other dynamics this guardian serves, in the order of its method's parts."""
        return tuple(k for k in self._parts if self._dynamics_args.get(k) is not None)

    def check_spaces(self, observation_space, action_space) -> None:
        other = self._delegate_for(action_space)
        if other is not None:
            return other.check_spaces(observation_space, action_space)
        type(self).own_check(self, action_space, also=tuple(self._parts[k] for k in self.served()))

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
