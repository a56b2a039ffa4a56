"""Importing a module the user names on a command line (``--agent module:Class``, ``--env module:Id``).

:func:`import_user_module` imports it and, when that fails, raises :class:`UserModuleError` with one
line that names the module, the file it was (or would be) loaded from and the import's own error:
a module missing, a module that fails to import (its own ``ImportError`` or any other exception)
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


def import_user_module(module: str, what: str) -> ModuleType:
    """Import ``module`` for ``what`` (e.g. ``"guardian 'mymod:Never'"``); :class:`UserModuleError`
    naming the module, its file and the cause if that fails in any way."""
    if not module or not all(part.isidentifier() for part in module.split(".")):
        raise UserModuleError(f"{what}: {module!r} is not a module name (expected dotted Python identifiers)")
    try:
        return importlib.import_module(module)
    except Exception as e:  # noqa: BLE001 - whatever the module raised while importing is the user's error to see
        place = where(module)
        if (
            isinstance(e, ModuleNotFoundError)
            and e.name is not None
            and (e.name == module or module.startswith(e.name + "."))
        ):
            cause = f"no module named {e.name!r} in the current directory ({os.getcwd()}) or the installed packages"
            raise UserModuleError(f"{what}: cannot import module {module!r}: {cause}") from None
        raise UserModuleError(
            f"{what}: cannot import module {module!r} (from {place}): {type(e).__name__}: {e}"
        ) from None
