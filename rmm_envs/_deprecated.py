"""Old names kept for the code that imports them: each warns (``DeprecationWarning``) when used.

:func:`renamed_attributes` gives a module a ``__getattr__`` (PEP 562) that answers its old
names with the new objects; :func:`moved_module` makes a module an alias of the one it moved to.
"""

from __future__ import annotations

import importlib
import warnings

__all__ = ["moved_module", "renamed_attributes"]


def renamed_attributes(module: str, names: dict[str, tuple[str, str]]):
    """A module ``__getattr__`` for ``names``: old name -> ("new.module:attr", the new name as
    the warning states it)."""

    def __getattr__(name: str):
        if name not in names:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        target, new = names[name]
        warnings.warn(f"{module}.{name} is deprecated: use {new}", DeprecationWarning, stacklevel=2)
        mod, _, attr = target.partition(":")
        return getattr(importlib.import_module(mod), attr)

    return __getattr__


def moved_module(old: str, new: str, namespace: dict) -> None:
    """Fill ``namespace`` (the old module's globals) with the public names of ``new``, warning once
    that ``old`` moved; the old import path keeps working."""
    warnings.warn(f"module {old} moved to {new}; import it from there", DeprecationWarning, stacklevel=3)
    target = importlib.import_module(new)
    public = getattr(target, "__all__", [n for n in vars(target) if not n.startswith("_")])
    namespace.update({n: getattr(target, n) for n in public})
    namespace["__all__"] = list(public)
