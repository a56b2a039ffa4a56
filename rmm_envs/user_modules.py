"""Importing a module the user names (``--agent module:Class``, ``--env module:Id``, a strategy's
``module:Class``, ``--failure module:callable``), and where it is found.

:func:`import_user_module` imports it or raises :class:`UserModuleError`, one line naming the
module, its file and the cause (missing, failing, shadowed), never a worker failure.
:func:`user_folders` searches the command's folder after every installed package and only for
a module named (or imported by one found there): a ``tqdm.py`` there never replaces the real
one, and a named module sharing an installed one's name is refused naming both.
:func:`named_modules` finds the ``module:Name`` references in options; :func:`only_consented`
limits the imports to the modules a command line named (``rmm-bench replay``).  Why:
docs/decisions/0026-user-modules.md.
"""

from __future__ import annotations

import contextlib
import importlib
import importlib.machinery
import importlib.util
import os
import sys
import threading
import traceback
from collections.abc import Iterable, Iterator
from types import FrameType, ModuleType

__all__ = [
    "OWN_PACKAGES",
    "UserModuleError",
    "find_module_spec",
    "import_user_module",
    "named_modules",
    "only_consented",
    "search_user_folders",
    "user_folders",
    "where",
]

#: This project's own packages: imported by name, never refused as a user's module.
OWN_PACKAGES = ("rmm_envs", "rmm_guardians", "rmm_bench")


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
    naming the module, its file and the cause if that fails in any way, if it is not consented to
    (:func:`only_consented`), or if the user's folders hold a module of its top-level name that an
    installed one would hide."""
    if not module or not all(part.isidentifier() for part in module.split(".")):
        raise UserModuleError(f"{what}: {module!r} is not a module name (expected dotted Python identifiers)")
    top = module.partition(".")[0]
    if _CONSENT and top not in OWN_PACKAGES:
        allowed, hint = _CONSENT[-1]
        if allowed is not None and module not in allowed:
            raise UserModuleError(f"{what}: module {module!r} is imported only with consent: {hint.format(module)}")
    with _requesting(top):
        _check_not_hidden(top, what)
        try:
            return importlib.import_module(module)
        except Exception as e:  # noqa: BLE001 - whatever the module raised while importing is the user's error to see
            raise _import_error(module, what, e) from None


def _import_error(module: str, what: str, e: Exception) -> UserModuleError:
    place = _found_without_import(module)  # where(module) would run a failing parent package again
    if (
        isinstance(e, ModuleNotFoundError)
        and e.name is not None
        and (e.name == module or module.startswith(e.name + "."))
    ):
        cause = f"no module named {e.name!r} in the current directory ({os.getcwd()}) or the installed packages"
        return UserModuleError(f"{what}: cannot import module {module!r}: {cause}")
    raised = _raised_in(e)
    cause = f"{type(e).__name__}: {e}"
    if raised is not None and (place is None or _short(raised[0]) != place):
        # another file raised it: a parent package's __init__.py, or a module it imports
        cause = f"{_short(raised[0])}:{raised[1]} raised {cause}"
    source = f" (from {place})" if place is not None else ""
    return UserModuleError(f"{what}: cannot import module {module!r}{source}: {cause}")


# -- the folders a user's own modules are found in ------------------------------------------------

_FOLDERS: list[str] = []  # searched after every installed package (user_folders)
_SERVED: set[str] = set()  # real paths of the files, and folders (ending in os.sep), found in _FOLDERS
_LOCAL = threading.local()  # .names: top-level names import_user_module is importing in this thread
_CONSENT: list[tuple[frozenset[str] | None, str]] = []  # only_consented's, innermost last


def _requested() -> list[str]:
    if not hasattr(_LOCAL, "names"):
        _LOCAL.names = []
    return _LOCAL.names


@contextlib.contextmanager
def _requesting(top: str) -> Iterator[None]:
    names = _requested()
    names.append(top)
    try:
        yield
    finally:
        names.pop()


def _in_folders(name: str) -> importlib.machinery.ModuleSpec | None:
    """The spec of top-level module ``name`` in the user's folders (nothing is executed)."""
    if not _FOLDERS or "." in name:
        return None
    try:
        return importlib.machinery.PathFinder.find_spec(name, list(_FOLDERS))
    except (ImportError, ValueError, OSError):
        return None


def _is_served(filename: str) -> bool:
    real = os.path.realpath(filename)
    return real in _SERVED or any(d.endswith(os.sep) and real.startswith(d) for d in _SERVED)


_SKIPPED_FRAMES = {os.path.realpath(importlib.__file__), os.path.realpath(__file__)}


def _imported_by_user_code() -> bool:
    """Whether the import under way comes from a file found in the user's folders."""
    frame: FrameType | None = sys._getframe(2)
    while frame is not None:
        name = frame.f_code.co_filename
        if not name.startswith("<") and os.path.realpath(name) not in _SKIPPED_FRAMES:
            return _is_served(name)
        frame = frame.f_back
    return False


class _UserFolderFinder:
    """The last finder of ``sys.meta_path``: a top-level module in the user's folders, found only
    when no installed one has its name and only for :func:`import_user_module` or for code that
    was itself found there (the user's module importing a helper beside it)."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        if path is not None or not _FOLDERS or (name not in _requested() and not _imported_by_user_code()):
            return None
        spec = _in_folders(name)
        if spec is not None:
            if spec.origin and spec.has_location:
                _SERVED.add(os.path.realpath(spec.origin))
            _SERVED.update(os.path.join(os.path.realpath(d), "") for d in spec.submodule_search_locations or ())
        return spec

    @staticmethod
    def invalidate_caches() -> None:
        pass


def search_user_folders(folders: Iterable[str]) -> list[str]:
    """Search ``folders`` (the directory a command ran in) for the modules a user names, after every
    installed package (see the module docstring); the folders searched before."""
    before = list(_FOLDERS)
    _FOLDERS[:] = list(dict.fromkeys(os.path.abspath(f) for f in folders))
    if _UserFolderFinder not in sys.meta_path:
        sys.meta_path.append(_UserFolderFinder)
    return before


@contextlib.contextmanager
def user_folders(folders: Iterable[str]) -> Iterator[None]:
    """:func:`search_user_folders` for the duration of a command (the folders before, after it)."""
    before = search_user_folders(folders)
    try:
        yield
    finally:
        _FOLDERS[:] = before


def find_module_spec(name: str) -> importlib.machinery.ModuleSpec | None:
    """``importlib.util.find_spec(name)`` that also finds a user's module in their folders (None:
    not found; a dotted name imports its parent packages, as ``find_spec`` does)."""
    try:
        with _requesting(name.partition(".")[0]):
            return importlib.util.find_spec(name)
    except (ImportError, ValueError):  # a parent package missing or failing: the import reports it
        return None


def _describe(spec) -> str:
    if spec.origin in ("built-in", "frozen"):
        return f"Python's {spec.origin} module"
    if spec.origin and spec.has_location:
        return _short(spec.origin)
    return "the folder " + ", ".join(_short(p) for p in spec.submodule_search_locations or ())


def _location(spec) -> set[str]:
    if spec.origin and spec.has_location:
        return {os.path.realpath(spec.origin)}
    return {os.path.realpath(p) for p in spec.submodule_search_locations or ()} or {str(spec.origin)}


def _installed_spec(top: str):
    """The spec ``import top`` finds outside the user's folders (nothing is executed)."""
    loaded = sys.modules.get(top)
    if loaded is not None:  # imported already: installed, unless a user's folder served it
        spec = getattr(loaded, "__spec__", None)
        return None if spec is None or any(_is_served(p) for p in _location(spec)) else spec
    path = [p for p in sys.path if os.path.abspath(p or os.curdir) not in _FOLDERS]
    for finder in sys.meta_path:
        if finder is _UserFolderFinder or not hasattr(finder, "find_spec"):
            continue
        try:
            if finder is importlib.machinery.PathFinder:
                spec = finder.find_spec(top, path)
            else:
                spec = finder.find_spec(top, None)
        except Exception:  # noqa: BLE001 - a third-party finder failing: no installed module found by it
            spec = None
        if spec is not None:
            return spec
    return None


def _check_not_hidden(top: str, what: str) -> None:
    """Refuse a user's module ``top`` that an installed module of the same name would hide."""
    mine = _in_folders(top)
    if mine is None or not (mine.origin and mine.has_location):
        return  # not the user's (or a bare folder of theirs, a namespace portion)
    theirs = _installed_spec(top)
    if theirs is None or _location(theirs) & _location(mine):
        return
    yours = os.path.dirname(mine.origin) + os.sep if mine.submodule_search_locations else mine.origin
    raise UserModuleError(
        f"{what}: module {top!r} is both your {yours} and the installed {top!r} ({_describe(theirs)}), which "
        f"comes first; rename yours (and the name you give it): a module of yours may not share its name with "
        "an installed one"
    )


@contextlib.contextmanager
def only_consented(modules: Iterable[str] | None, hint: str) -> Iterator[None]:
    """Within: :func:`import_user_module` imports only ``modules`` (None: any) and this project's own
    packages, refusing any other with one line ending in ``hint.format(module)`` (how to consent)."""
    _CONSENT.append((None if modules is None else frozenset(modules), hint))
    try:
        yield
    finally:
        _CONSENT.pop()


def _strings(value) -> Iterator[str]:
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _strings(v)


def _items(text: str) -> Iterator[str]:
    """``text``'s items at its top-level commas (a strategies spec: ``"+mod:Cls(1, 2), Commit"``)."""
    depth, start = 0, 0
    for i, ch in enumerate(text + ","):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == "," and depth <= 0:
            yield text[start:i].strip()
            start = i + 1


def _dotted(name: str) -> bool:
    return bool(name) and all(part.isidentifier() for part in name.split("."))


def named_modules(value) -> dict[str, str]:
    """The modules ``value`` (an option, or a dict or list of them) names in ``module:Name`` form,
    each with the string naming it: a string, or an item of a comma-separated spec, that is
    ``module:Name``, optionally with a leading ``+``/``-`` and a trailing ``(arguments)``
    (``"+evil_strat:Evil(1)"`` names ``evil_strat``; ``"fixed:1"`` and ``"Commit(5)"`` name none)."""
    out: dict[str, str] = {}
    for text in _strings(value):
        for item in _items(text):
            ref = (item[1:] if item[:1] in "+-" else item).partition("(")[0].strip()
            module, colon, attr = ref.partition(":")
            if colon and _dotted(module) and _dotted(attr):
                out.setdefault(module, text)
    return out
