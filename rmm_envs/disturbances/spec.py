"""What a disturbance is: its kinds, levels, shapes and string form, read and checked (see
:mod:`rmm_envs.disturbances`)."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["KINDS", "SHAPES", "Disturbance", "DisturbanceError", "SystemSupport", "kind_code", "parse_disturbances"]

SHAPES = ("white", "uniform", "step", "periodic", "impulse")


@dataclass(frozen=True)
class _Kind:
    shapes: tuple[str, ...]  # allowed, the default first
    level: str  # what the level is, for messages
    target: str  # "obs", "act", "rate" or "params"
    integer: bool = False
    probability: bool = False


KINDS: dict[str, _Kind] = {
    "obs-noise": _Kind(SHAPES, "a standard deviation >= 0", "obs"),
    "obs-bias": _Kind(("uniform",), "an offset (any finite number)", "obs"),
    "ray-dropout": _Kind(("white",), "a probability in [0, 1]", "obs", probability=True),
    "act-noise": _Kind(SHAPES, "a standard deviation >= 0 (a fraction of the half range)", "act"),
    "act-gain": _Kind(("uniform",), "a relative gain error in [0, 1]", "act", probability=True),
    "act-delay": _Kind(("none",), "a whole number of steps >= 0", "act", integer=True),
    "dyn-rate": _Kind(("uniform", "white", "step", "periodic"), "a bound >= 0", "rate"),
    "impulse": _Kind(("impulse",), "a push size >= 0", "rate"),
    "mismatch": _Kind(("uniform",), "a relative range in [0, 1)", "params"),
}


class DisturbanceError(ValueError):
    """A disturbance that cannot be read or that a system does not support (one line)."""


@dataclass(frozen=True)
class Disturbance:
    """One kind of disturbance at one level (see the module's table)."""

    kind: str
    level: float
    shape: str = ""  # "" -> the kind's default
    on: tuple[str, ...] = ()  # components; () -> the kind's default

    def __post_init__(self) -> None:
        spec = KINDS.get(self.kind)
        if spec is None:
            raise DisturbanceError(f"unknown disturbance kind {self.kind!r}; expected one of {', '.join(KINDS)}")
        level = self.level
        if isinstance(level, bool) or not isinstance(level, (int, float, np.integer, np.floating)):
            raise DisturbanceError(f"{self.kind}: level {level!r} is not a number; expected {spec.level}")
        level = float(level)
        if not math.isfinite(level):
            raise DisturbanceError(f"{self.kind}: level {level!r} is not finite; expected {spec.level}")
        if spec.integer and (level < 0 or level != int(level)):
            raise DisturbanceError(f"{self.kind}: level {level!r}; expected {spec.level}")
        if spec.probability and not 0.0 <= level <= 1.0:
            raise DisturbanceError(f"{self.kind}: level {level!r} is outside [0, 1]; expected {spec.level}")
        if self.kind == "mismatch" and not 0.0 <= level < 1.0:
            raise DisturbanceError(f"{self.kind}: level {level!r} is outside [0, 1); expected {spec.level}")
        if self.kind != "obs-bias" and level < 0:
            raise DisturbanceError(f"{self.kind}: level {level!r} is negative; expected {spec.level}")
        object.__setattr__(self, "level", level)
        shape = self.shape or spec.shapes[0]
        if shape not in spec.shapes:
            raise DisturbanceError(f"{self.kind}: shape {shape!r} is not one of this kind's ({', '.join(spec.shapes)})")
        object.__setattr__(self, "shape", shape)
        on = tuple(self.on)
        if len(set(on)) != len(on) or any(not isinstance(c, str) or not c for c in on):
            raise DisturbanceError(f"{self.kind}: components {on!r} must be distinct names")
        if on and spec.target in ("act", "params") and self.kind != "mismatch":
            raise DisturbanceError(f"{self.kind}: acts on the whole control; components {on!r} are not taken")
        object.__setattr__(self, "on", tuple(sorted(on)))

    @property
    def target(self) -> str:
        return KINDS[self.kind].target

    def __str__(self) -> str:
        level = str(int(self.level)) if KINDS[self.kind].integer else repr(self.level)
        on = "." + "+".join(self.on) if self.on else ""
        default = KINDS[self.kind].shapes[0]
        shape = "" if self.shape == default else "@" + self.shape
        return f"{self.kind}{on}={level}{shape}"

    @classmethod
    def parse(cls, text: str) -> Disturbance:
        """Read ``KIND[.COMPONENT+...]=LEVEL[@SHAPE]``."""
        if not isinstance(text, str):
            raise DisturbanceError(f"a disturbance is a string KIND[.COMPONENTS]=LEVEL[@SHAPE], got {text!r}")
        head, eq, tail = text.strip().partition("=")
        if not eq or not head or not tail:
            raise DisturbanceError(
                f"disturbance {text!r}: expected KIND[.COMPONENTS]=LEVEL[@SHAPE], e.g. obs-noise.rays=0.1"
            )
        kind, _, comps = head.partition(".")
        level_text, _, shape = tail.partition("@")
        try:
            level = float(level_text)
        except ValueError:
            raise DisturbanceError(
                f"disturbance {text!r}: level {level_text!r} is not a number; expected {_level_of(kind)}"
            ) from None
        on = tuple(comps.split("+")) if comps else ()
        return cls(kind.strip(), level, shape.strip(), on)


def _level_of(kind: str) -> str:
    spec = KINDS.get(kind)
    return spec.level if spec else "a number"


def parse_disturbances(spec) -> tuple[Disturbance, ...]:
    """A tuple of :class:`Disturbance` from ``None`` (none), a string (``;`` between items), or a
    sequence of strings and :class:`Disturbance`; one disturbance per kind and component set."""
    if spec is None:
        return ()
    items: Iterable
    if isinstance(spec, str):
        items = [s for s in spec.split(";") if s.strip()]
    elif isinstance(spec, Disturbance):
        items = [spec]
    elif isinstance(spec, Sequence):
        items = spec
    else:
        raise DisturbanceError(
            f"disturbances must be a string or a list of KIND=LEVEL strings, got {type(spec).__name__} {spec!r}"
        )
    out = [d if isinstance(d, Disturbance) else Disturbance.parse(d) for d in items]
    seen: set[tuple[str, tuple[str, ...]]] = set()
    for d in out:
        key = (d.kind, d.on)
        if key in seen:
            raise DisturbanceError(f"disturbance {d} is given twice; give each kind and component set once")
        seen.add(key)
    return tuple(out)


@dataclass(frozen=True)
class SystemSupport:
    """What a system offers disturbances.

    Args:
        dt: the sim-time step the streams are indexed by (the env's step), seconds.
        horizon: the episode's sim-time limit, seconds (onsets and impulses fall in its first half).
        layout: the observation's fields (``rmm_envs.autonomy.ObservationLayout``) or ``None``.
        obs_high: the observation's upper bounds (a ray's maximum range for dropouts).
        action_low, action_high: the continuous control's bounds (act kinds clip to them).
        rates: the state components a rate disturbance adds to, ``name -> index`` (empty: none).
        parameters: the plant's nominal parameters a mismatch may scale, ``name -> value``.
    """

    dt: float
    horizon: float
    layout: object | None = None
    obs_high: np.ndarray | None = None
    action_low: np.ndarray | None = None
    action_high: np.ndarray | None = None
    rates: Mapping[str, int] = field(default_factory=dict)
    parameters: Mapping[str, float] = field(default_factory=dict)
    system: str = "this system"

    def obs_fields(self) -> tuple[str, ...]:
        return tuple(getattr(self.layout, "names", ()))

    def check(self, disturbances: Sequence[Disturbance]) -> None:
        """Refuse, in one line, a disturbance this system cannot apply."""
        for d in disturbances:
            target = d.target
            if target == "obs":
                names = self.obs_fields()
                if not names:
                    raise DisturbanceError(f"{d}: {self.system} has no observation layout to disturb")
                wanted = d.on or (("rays",) if d.kind in ("obs-bias", "ray-dropout") else ())
                if d.kind == "ray-dropout" and d.on and d.on != ("rays",):
                    raise DisturbanceError(f"{d}: ray-dropout acts on the rays only, not {'+'.join(d.on)}")
                for c in wanted:
                    if c not in names:
                        raise DisturbanceError(
                            f"{d}: {self.system}'s observation has no field {c!r}; it has {', '.join(names)}"
                        )
                if d.kind == "ray-dropout" and (
                    self.obs_high is None or not np.all(np.isfinite(np.asarray(self.obs_high)[self.layout["rays"]]))  # type: ignore[index]
                ):
                    raise DisturbanceError(f"{d}: {self.system}'s rays have no maximum range to read on a dropout")
            elif target == "act":
                if self.action_low is None or self.action_high is None:
                    raise DisturbanceError(f"{d}: {self.system} has no continuous control to disturb")
            elif target == "rate":
                if not self.rates:
                    raise DisturbanceError(f"{d}: {self.system} takes no rate disturbance")
                for c in d.on:
                    if c not in self.rates:
                        raise DisturbanceError(
                            f"{d}: {self.system} has no rate component {c!r}; it has {', '.join(self.rates)}"
                        )
            elif target == "params":
                if not self.parameters:
                    raise DisturbanceError(f"{d}: {self.system} has no parameters a mismatch can scale")
                for c in d.on:
                    if c not in self.parameters:
                        raise DisturbanceError(
                            f"{d}: {self.system} has no parameter {c!r}; it has {', '.join(self.parameters)}"
                        )


def kind_code(kind: str) -> int:
    """A kind's fixed number in the seed sequence (its place in :data:`KINDS`)."""
    return list(KINDS).index(kind)
