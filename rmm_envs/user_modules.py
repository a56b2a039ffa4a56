"""Importing a module the user names on a command line (``--agent module:Class``, ``--env module:Id``).

:func:`import_user_module` imports it and, when that fails, raises :class:`UserModuleError` with one
line that names the module, the file it was (or would be) loaded from and the import's own error:
a module missing, a module that fails to import (its own ``ImportError`` or any other exception;
when another file raised it, such as a parent package's ``__init__.py``, that file and line too)
and a module shadowed by a same-named folder or file earlier on the import path all read as what
they are, never as a worker or memory failure.  :func:`where` names the file of an imported
module, for the messages that follow an import (an attribute it lacks).
"""

from __future__ import annotations

import importlib
import importlib.util
import os
from types import ModuleType

__all__ = ["UserModuleError", "import_user_module", "where"]


class UserModuleError(ValueError):
    """A user-named module could not be imported, or lacks the attribute asked for."""


def where(module: ModuleType | str) -> str:
    """The file a module was (or would be) loaded from: its ``__file__``, a namespace package's
    folders, or ``"not found on the import path"``."""
    if isinstance(module, str):
        try:
            spec = importlib.util.find_spec(module)
        except (ImportError, ValueError):  # a parent package that is missing or fails to import
            spec = None
        if spec is None:
            return "not found on the import path"
        origin = spec.origin if spec.origin not in (None, "namespace") else None
        locations = list(spec.submodule_search_locations or [])
    else:
        origin = getattr(module, "__file__", None)
        locations = list(getattr(module, "__path__", []) or [])
    if origin:
        return _short(origin)
    if locations:
        return "the folder " + ", ".join(_short(p) for p in locations) + " (a namespace package: no __init__.py)"
    return "a built-in module"


def _short(path: str) -> str:
    try:
        rel = os.path.relpath(path)
    except ValueError:  # another drive
        return path
    return rel if not rel.startswith("..") else path


def _found_without_import(module: str) -> str | None:
    """The file of ``module`` as the import path finds it, without executing any package
    ``__init__.py`` on the way (``None`` when it is not found there)."""
    import importlib.machinery
    import sys

    spec = None
    parts = module.split(".")
    for i, part in enumerate(parts):
        name = ".".join(parts[: i + 1])
        loaded = sys.modules.get(name)
        try:
            if loaded is not None:
                spec = getattr(loaded, "__spec__", None)
            elif i == 0:
                spec = importlib.machinery.PathFinder.find_spec(part) or importlib.util.find_spec(part)
            else:
                locations = list(spec.submodule_search_locations or []) if spec is not None else []
                spec = importlib.machinery.PathFinder.find_spec(name, locations) if locations else None
        except (ImportError, ValueError):
            spec = None
        if spec is None:
            return None
    if spec is None:  # an empty name
        return None
    if spec.origin not in (None, "namespace", "built-in", "frozen"):
        return _short(spec.origin)
    if spec.submodule_search_locations:
        return (
            "the folder "
            + ", ".join(_short(p) for p in spec.submodule_search_locations)
            + (" (a namespace package: no __init__.py)")
        )
    return "a built-in module"


def _raised_in(e: BaseException) -> tuple[str, int] | None:
    """``(file, line)`` of the code whose import raised ``e``: the innermost module-level frame
    of its traceback outside importlib (the innermost frame outside importlib if none is)."""
    import traceback

    skip = (os.path.realpath(importlib.__file__), os.path.realpath(__file__))
    frames = [
        f
        for f in traceback.extract_tb(e.__traceback__)
        if not f.filename.startswith("<") and os.path.realpath(f.filename) not in skip
    ]
    top = [f for f in frames if f.name == "<module>"] or frames
    return (top[-1].filename, top[-1].lineno or 0) if top else None


def import_user_module(module: str, what: str) -> ModuleType:
    """Import ``module`` for ``what`` (e.g. ``"guardian 'mymod:Never'"``); :class:`UserModuleError`
    naming the module, its file and the cause if that fails in any way."""
    if not module or not all(part.isidentifier() for part in module.split(".")):
        raise UserModuleError(f"{what}: {module!r} is not a module name (expected dotted Python identifiers)")
    try:
        return importlib.import_module(module)
    except Exception as e:  # noqa: BLE001 - whatever the module raised while importing is the user's error to see
        place = _found_without_import(module)  # where(module) would run a failing parent package again
        if (
            isinstance(e, ModuleNotFoundError)
            and e.name is not None
            and (e.name == module or module.startswith(e.name + "."))
        ):
            cause = f"no module named {e.name!r} in the current directory ({os.getcwd()}) or the installed packages"
            raise UserModuleError(f"{what}: cannot import module {module!r}: {cause}") from None
        raised = _raised_in(e)
        cause = f"{type(e).__name__}: {e}"
        if raised is not None and (place is None or _short(raised[0]) != place):
            # another file raised it: a parent package's __init__.py, or a module it imports
            cause = f"{_short(raised[0])}:{raised[1]} raised {cause}"
        source = f" (from {place})" if place is not None else ""
        raise UserModuleError(f"{what}: cannot import module {module!r}{source}: {cause}") from None
