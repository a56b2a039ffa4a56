"""The parallel-autonomy contract: how a guardian and an environment talk.

A parallel-autonomy env has a built-in driver; each step a guardian's action says whether it
takes control and with which control vector.  This module offers:

* :class:`GuardianActionSpace`: the action's space (a Gymnasium ``Dict``: ``active_ctrl`` and
  one shape-(1,) box per control), with ``inactive()``, ``active(u)``, ``parse(action)``;
* :class:`SystemContract` (``space.contract``, :func:`contract`): the name of the dynamics it drives
  (guardians dispatch on it, never on control names), control names, bounds, safe default and obstacles;
* :class:`SafeDefault`: a system's safe control (what ``brakes`` applies);
* :class:`ObservationBox` / :class:`ObservationLayout` / :func:`layout`: named observation fields;
* :func:`inactive`, :func:`active`, :func:`parse`: the same given the space.

The rules (clipping, error messages, float64 boxes) are in ``docs/concepts.md``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces

from rmm_envs.observation_layout import ObservationBox, ObservationLayout, layout

__all__ = [
    "ACTIVE",
    "GENERIC",
    "GuardianActionSpace",
    "ObservationBox",
    "ObservationLayout",
    "SafeDefault",
    "SystemContract",
    "active",
    "contract",
    "inactive",
    "layout",
    "parse",
]

ACTIVE = "active_ctrl"  # the action field that says whether the guardian takes control
#: The dynamics name of an env no built-in guardian models (a third-party simulator made a guarded env).
GENERIC = "generic"


class SafeDefault:
    """A system's safe default control (what the ``brakes`` guardian applies); subclass per system.

    :meth:`policy` is called once per episode and returns the episode's policy, a function
    from the observation to the control vector (within the space's bounds).  ``options`` are
    the keyword options a subclass's :meth:`policy` accepts (e.g. Dubins4D's ``turn``); others
    are refused with a ``ValueError`` naming them.
    """

    #: what the safe default does, in words (error messages and reports show it)
    description: str = "a safe default control"
    #: keyword options :meth:`policy` accepts
    options: tuple[str, ...] = ()

    def check_options(self, options: dict) -> None:
        unknown = sorted(set(options) - set(self.options))
        if unknown:
            accepted = ", ".join(repr(o) for o in self.options) or "none"
            raise ValueError(
                f"the safe default of this env ({self.description}) takes no option(s) {unknown}; "
                f"it accepts: {accepted}"
            )

    def policy(self, space: GuardianActionSpace, rng: np.random.Generator, **options):  # pragma: no cover - abstract
        """``observation -> control vector`` for one episode; ``rng`` for any per-episode draw."""
        raise NotImplementedError


@dataclass(frozen=True)
class SystemContract:
    """What a guardian may know of the system an env's action space drives (``space.contract``).

    ``dynamics_name`` names the dynamics (a guardian that models one dynamics serves exactly the
    spaces that name it; :data:`GENERIC`: no built-in model); ``controls``, ``control_low`` and
    ``control_high`` the control vector's fields and bounds; ``safe_default`` and
    ``obstacle_shapes`` as given to :class:`GuardianActionSpace`."""

    dynamics_name: str
    controls: tuple[str, ...]
    control_low: tuple[float, ...]
    control_high: tuple[float, ...]
    safe_default: SafeDefault | None = None
    obstacle_shapes: tuple[str, ...] | None = None


class GuardianActionSpace(spaces.Dict):
    """``Dict(active_ctrl=Discrete(2), <name>=Box(low_i, high_i, (1,)) for each control)``.

    Args:
        controls: the action field of each component of the control vector, in the order of
            the dynamics' control vector (e.g. ``("turnrate_ctrl", "accel_ctrl")``).
        low, high: the control bounds, one number per control (``low <= high``, finite).
        seed: as for ``gymnasium.spaces.Dict``.
        safe_default: the system's :class:`SafeDefault` (``None``: the env states none).
        obstacle_shapes: the shapes of the obstacles in the env's world (e.g. ``("circle",
            "polygon")``), for guardians whose model of the privileged obstacles assumes a shape
            (``cbf`` and ``hj`` need circles); ``None``: not stated (the circle envs).
        dynamics_name: the dynamics' name (:class:`SystemContract`), stated by the env from its
            dynamics module's ``DYNAMICS_NAME``; default :data:`GENERIC`.

    The fields are stored in Gymnasium's default (sorted) key order, so sampling, seeding and
    flattening behave exactly as for the plain ``Dict`` with the same fields; the control
    order lives in :attr:`controls`.  The continuous fields are float64 boxes, the precision the
    systems integrate in: the driver's control (``info["nominal_control"]``) goes through
    :meth:`active` unrounded, so a guardian that hands it back applies exactly what the driver
    would have (a float32 box would round it, and the episode would drift from the driver's).
    """

    def __init__(
        self,
        controls: Sequence[str],
        low: Iterable[float],
        high: Iterable[float],
        seed=None,
        safe_default: SafeDefault | None = None,
        obstacle_shapes: Sequence[str] | None = None,
        dynamics_name: str = GENERIC,
    ) -> None:
        controls = tuple(controls)
        if not isinstance(dynamics_name, str) or not dynamics_name:
            raise ValueError(
                f"dynamics_name must be a non-empty dynamics name (e.g. {GENERIC!r}), got {dynamics_name!r}"
            )
        lo = np.asarray(list(low), dtype=float).reshape(-1)
        hi = np.asarray(list(high), dtype=float).reshape(-1)
        if not controls or len(set(controls)) != len(controls) or not all(isinstance(c, str) and c for c in controls):
            raise ValueError(f"controls must be distinct non-empty field names, got {controls!r}")
        if ACTIVE in controls:
            raise ValueError(f"{ACTIVE!r} is the activation flag and cannot name a control")
        if lo.shape != (len(controls),) or hi.shape != (len(controls),):
            raise ValueError(f"low and high need one bound per control {controls}, got {lo.tolist()} and {hi.tolist()}")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo <= hi)):
            raise ValueError(
                f"control bounds must be finite with low <= high, got low={lo.tolist()} high={hi.tolist()}"
            )
        fields: dict[str, spaces.Space] = {ACTIVE: spaces.Discrete(2)}
        boxes: dict[str, spaces.Box] = {}
        for name, a, b in zip(controls, lo, hi, strict=True):
            fields[name] = boxes[name] = spaces.Box(a, b, shape=(1,), dtype=np.float64)
        super().__init__(fields, seed=seed)
        if safe_default is not None and not isinstance(safe_default, SafeDefault):
            raise TypeError(f"safe_default must be a rmm_envs.autonomy.SafeDefault, got {safe_default!r}")
        self.controls = controls
        self.dynamics_name = dynamics_name
        self.safe_default = safe_default
        self.obstacle_shapes = None if obstacle_shapes is None else tuple(obstacle_shapes)
        # the bounds actions are clipped to: those of the boxes
        self.control_low = np.array([float(boxes[c].low[0]) for c in controls])
        self.control_high = np.array([float(boxes[c].high[0]) for c in controls])

    @classmethod
    def for_dynamics(
        cls,
        dynamics: Any,
        controls: Sequence[str],
        seed=None,
        safe_default: SafeDefault | None = None,
        obstacle_shapes: Sequence[str] | None = None,
        dynamics_name: str = GENERIC,
    ) -> GuardianActionSpace:
        """The action space of dynamics whose object has ``control_low``/``control_high``."""
        return cls(
            controls,
            np.asarray(dynamics.control_low, float),
            np.asarray(dynamics.control_high, float),
            seed=seed,
            safe_default=safe_default,
            obstacle_shapes=obstacle_shapes,
            dynamics_name=dynamics_name,
        )

    @property
    def contract(self) -> SystemContract:
        """The system's contract: the dynamics' name, controls, bounds, safe default, obstacle shapes."""
        return SystemContract(
            self.dynamics_name,
            self.controls,
            tuple(self.control_low.tolist()),
            tuple(self.control_high.tolist()),
            self.safe_default,
            self.obstacle_shapes,
        )

    @property
    def control_dim(self) -> int:
        return len(self.controls)

    def inactive(self) -> dict:
        """The driver controls this step (the control fields are zeros and ignored)."""
        action: dict[str, Any] = {ACTIVE: 0}
        for c in self.controls:
            action[c] = np.zeros(1)
        return action

    def active(self, control) -> dict:
        """Take control and apply the control vector ``control`` (one number per control)."""
        # one float64 buffer (a copy: the caller's array is never aliased), one field per element
        u = np.array(control, dtype=float).reshape(-1)
        if u.shape != (len(self.controls),):
            raise ValueError(f"control must have one value per control {self.controls}, got {control!r}")
        action: dict[str, Any] = {ACTIVE: 1}
        for i, c in enumerate(self.controls):
            action[c] = u[i : i + 1]
        return action

    @property
    def flat_dim(self) -> int:
        """Length of the flat action of :meth:`from_unit`: the flag, then one number per control."""
        return 1 + len(self.controls)

    def from_unit(self, flat) -> dict:
        """The action of a flat vector ``[active, z_1, ..., z_c]`` in the unit box (what RL
        libraries train on; :class:`rmm_envs.wrappers.FlattenGuardianAction`'s action space and
        :class:`rmm_guardians.wrapped.SB3Guardian`'s input, so a policy trained through the one acts
        the same through the other): ``active > 0.5`` takes control, and ``z_i in [-1, 1]`` maps
        linearly onto ``[low_i, high_i]`` (``-1`` the lower bound, ``+1`` the upper; values
        outside ``[-1, 1]`` are clipped first).  Non-finite numbers raise ``ValueError`` naming
        the index."""
        a = np.asarray(flat, dtype=float).reshape(-1)
        if a.shape != (self.flat_dim,):
            raise ValueError(
                f"a flat guardian action has {self.flat_dim} numbers [active, "
                f"{', '.join(self.controls)}], got shape {np.shape(flat)}"
            )
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise ValueError(f"flat guardian action index {int(bad[0])} must be finite, got {a[bad[0]]}")
        if a[0] <= 0.5:
            return self.inactive()
        z = np.clip(a[1:], -1.0, 1.0)
        return self.active(self.control_low + (z + 1.0) * 0.5 * (self.control_high - self.control_low))

    def to_unit(self, control) -> np.ndarray:
        """The unit-box coordinates ``z`` of a control vector (the inverse of :meth:`from_unit`'s
        scaling; ``0`` for a control whose bounds coincide)."""
        u = np.asarray(control, dtype=float).reshape(-1)
        span = self.control_high - self.control_low
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(span > 0, 2.0 * (u - self.control_low) / span - 1.0, 0.0)

    def parse(self, action) -> tuple[bool, np.ndarray]:
        """Validate ``action``; return ``(active, control vector clipped to the bounds)``."""
        keys = [ACTIVE, *self.controls]
        if not isinstance(action, dict):
            try:
                action = dict(action)
            except (TypeError, ValueError):
                raise ValueError(
                    f"action must be a dict with keys {', '.join(keys)} ({self}), got {type(action).__name__}"
                ) from None
        for key in keys:
            if key not in action:
                raise ValueError(f"action is missing field {key!r}; expected the keys of {self}")
        extra = set(action) - set(keys)
        if extra:
            raise ValueError(f"action has unknown fields {sorted(extra, key=str)}; expected the keys of {self}")
        flag = np.asarray(action[ACTIVE])
        if (
            flag.size != 1
            or flag.dtype.kind not in "biuf"
            or flag.ndim > 1
            or float(flag.reshape(-1)[0]) not in (0.0, 1.0)
        ):
            raise ValueError(f"action field {ACTIVE!r} must be 0 or 1 (Discrete(2)), got {action[ACTIVE]!r}")
        u = np.empty(len(self.controls))
        for i, c in enumerate(self.controls):
            u[i] = _bounded_scalar(action[c], c, self.spaces[c], self.control_low[i], self.control_high[i])
        return float(flag.reshape(-1)[0]) == 1.0, u

    def parse_batch(self, actions, n: int, batch_space=None) -> tuple[np.ndarray, np.ndarray]:
        """Validate the actions of ``n`` sub-envs (a dict of arrays, one entry per sub-env, shape
        ``(n,)`` or ``(n, 1)`` per field); return ``(active (n,) bool, controls (n, c) clipped)``.
        Errors name the field and the first bad sub-env; ``batch_space`` is named in them."""
        keys = [ACTIVE, *self.controls]
        where = batch_space if batch_space is not None else f"{n} x {self}"
        if not isinstance(actions, dict):
            try:
                actions = dict(actions)
            except (TypeError, ValueError):
                raise ValueError(
                    f"actions must be a dict of arrays with keys {keys} ({where}), got {type(actions).__name__}"
                ) from None
        missing = [k for k in keys if k not in actions]
        if missing:
            raise ValueError(f"actions are missing field {missing[0]!r}; expected the keys of {where}")
        extra = sorted(set(actions) - set(keys), key=str)
        if extra:
            raise ValueError(f"actions have unknown fields {extra}; expected the keys of {where}")
        arrs = {}
        for key in keys:
            arr = np.asarray(actions[key])
            if arr.dtype.kind not in "biuf" or arr.shape not in ((n,), (n, 1)):
                raise ValueError(
                    f"action field {key!r} must be {n} numbers, shape ({n},) or ({n}, 1), "
                    f"got {arr.dtype} array of shape {arr.shape}"
                )
            arrs[key] = arr.reshape(n)
        flag = arrs[ACTIVE]
        act = flag == 1
        bad = ~(act | (flag == 0))
        if bad.any():
            i = int(np.argmax(bad))
            raise ValueError(f"action field {ACTIVE!r} of sub-env {i} must be 0 or 1 (Discrete(2)), got {flag[i]!r}")
        ctrl = np.empty((n, len(self.controls)))
        for j, c in enumerate(self.controls):
            ctrl[:, j] = arrs[c]
        if not np.isfinite(ctrl).all():
            i, j = np.argwhere(~np.isfinite(ctrl))[0]
            raise ValueError(f"action field {self.controls[j]!r} of sub-env {i} must be finite, got {ctrl[i, j]!r}")
        np.minimum(np.maximum(ctrl, self.control_low, out=ctrl), self.control_high, out=ctrl)
        return act, ctrl


def _bounded_scalar(value, field: str, space: spaces.Space, low: float, high: float) -> float:
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu" or arr.size != 1 or arr.ndim > 1:
        raise ValueError(f"action field {field!r} must be a number or a shape-(1,) array in {space}, got {value!r}")
    x = float(arr.reshape(-1)[0])
    if not math.isfinite(x):
        raise ValueError(f"action field {field!r} must be finite (space {space}), got {x}")
    return min(max(x, low), high)


def _action_space(space) -> GuardianActionSpace:
    if not isinstance(space, GuardianActionSpace):
        raise TypeError(
            f"expected the action space of a parallel-autonomy env (rmm_envs.autonomy.GuardianActionSpace), got {space!r}"
        )
    return space


def inactive(space: GuardianActionSpace) -> dict:
    """The action of ``space`` that leaves control with the driver."""
    return _action_space(space).inactive()


def active(space: GuardianActionSpace, control) -> dict:
    """The action of ``space`` that takes control and applies ``control``."""
    return _action_space(space).active(control)


def contract(space) -> SystemContract:
    """The :class:`SystemContract` of an env's action space (``TypeError`` for another space)."""
    return _action_space(space).contract


def parse(action, space: GuardianActionSpace) -> tuple[bool, np.ndarray]:
    """Validate ``action`` against ``space``; ``(active, control clipped to the bounds)``."""
    return _action_space(space).parse(action)
