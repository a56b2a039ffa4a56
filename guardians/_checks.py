"""Argument checks shared by the guardians' constructors: a bad value is refused with a
message that names the argument, the value and what was expected.  :class:`Settings` is the
base of a guardian's frozen settings object (checked once, with named presets), and
:func:`settings_signature` gives the constructor that builds one its keyword signature."""

from __future__ import annotations

import dataclasses
import inspect
import math
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

if TYPE_CHECKING:
    from typing import Self  # Python 3.11; only the type checker reads it (annotations are strings)

__all__ = ["Settings", "finite", "integer", "number_pair", "settings_signature"]


class Settings:
    """Base of a frozen dataclass of a guardian's settings: subclasses check and normalise every
    value in ``__post_init__`` (through ``_set``) and list named presets in ``PRESETS``."""

    PRESETS: ClassVar[dict[str, Any]] = {}
    # set by @dataclass on every subclass (an annotation only: the base itself is no dataclass);
    # declared so the type checker knows a Settings is a dataclass instance
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]

    def _set(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def replace(self, **changes: Any) -> Self:
        """These settings with ``changes`` (checked again); an unknown name is a ``TypeError``
        naming it and the settings there are."""
        unknown = sorted(set(changes) - set(self.names()))
        if unknown:
            raise TypeError(
                f"unknown {type(self).__name__} setting(s) {unknown}; the settings are: {', '.join(self.names())}"
            )
        return dataclasses.replace(self, **changes) if changes else self

    @classmethod
    def preset(cls, name: str, **changes: Any) -> Self:
        """The preset ``name`` (a key of ``PRESETS``) with ``changes``."""
        if name not in cls.PRESETS:
            raise ValueError(f"unknown {cls.__name__} preset {name!r}; the presets are: {sorted(cls.PRESETS)}")
        return cls.PRESETS[name].replace(**changes)


def settings_signature(cls: type[Settings], default: Settings) -> inspect.Signature:
    """The signature of a constructor ``(self, settings=None, **options)`` that builds ``cls``
    settings from ``default`` and ``options``: one keyword parameter per setting, with
    ``default``'s values, so introspection (``rmm-bench``'s ``threads``, ``help()``) sees them."""
    params = [
        inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD),
        inspect.Parameter("settings", inspect.Parameter.POSITIONAL_OR_KEYWORD, default=None),
    ]
    params += [inspect.Parameter(n, inspect.Parameter.KEYWORD_ONLY, default=getattr(default, n)) for n in cls.names()]
    return inspect.Signature(params)


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
