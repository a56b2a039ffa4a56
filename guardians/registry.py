"""Guardian registry: names to guardians.

Built in: ``lrmm``, ``cbf``, ``hj`` (the best defaults this project can justify, each
explained in its module docstring), ``lrmm-paper``, ``cbf-paper``, ``hj-paper`` (the paper's
rules, exactly, for reproduction), and the baselines ``random``, ``inactive``, ``brakes``.
Two named sets: ``all`` (:data:`DEFAULT_SET`, what ``rmm-bench --agent all`` runs) and
``paper`` (:data:`PAPER_SET`, the paper's Table I agents with the paper's rules).
Third-party guardians register through the entry-point group ``rmm_envs.guardians``
(``name = "package.module:Class"``) or are named directly as ``module:Class``.
"""

from __future__ import annotations

import importlib.util
import inspect
from importlib.metadata import entry_points
from typing import Any

from rmm_envs.user_modules import UserModuleError, import_user_module, where
from rmm_guardians.base import Guardian

__all__ = [
    "DEFAULT_SET",
    "ENTRY_POINT_GROUP",
    "PAPER_SET",
    "accepts_argument",
    "available_guardians",
    "guardian_set",
    "load_guardian_class",
    "make_guardian",
]

ENTRY_POINT_GROUP = "rmm_envs.guardians"

BUILTIN = {
    "lrmm": "rmm_guardians.lrmm.guardian:LRMMGuardian",
    "lrmm-paper": "rmm_guardians.lrmm.guardian:LRMMPaperGuardian",
    "cbf": "rmm_guardians.cbf:CBFGuardian",
    "cbf-paper": "rmm_guardians.cbf:CBFPaperGuardian",
    "hj": "rmm_guardians.hj.guardian:HJGuardian",
    "hj-paper": "rmm_guardians.hj.guardian:HJPaperGuardian",
    "random": "rmm_guardians.baselines:RandomGuardian",
    "inactive": "rmm_guardians.baselines:InactiveGuardian",
    "brakes": "rmm_guardians.baselines:BrakesGuardian",
}

#: The suite's guardians at their defaults: ``rmm-bench --agent all``.
DEFAULT_SET = ("lrmm", "cbf", "hj", "random", "inactive", "brakes")
#: The paper's Table I agents with the paper's rules: ``rmm-bench --agent paper``.
PAPER_SET = ("lrmm-paper", "cbf-paper", "hj-paper", "random", "inactive", "brakes")
SETS = {"all": DEFAULT_SET, "paper": PAPER_SET}


def guardian_set(name: str) -> list[str] | None:
    """The available members of a named set (``"all"`` or ``"paper"``); None for other names."""
    members = SETS.get(name.strip())
    if members is None:
        return None
    available = set(available_guardians())
    return [n for n in members if n in available]


def _entry_points() -> dict[str, Any]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def _import(spec: str):
    module, _, attr = spec.partition(":")
    if not module or not attr:
        raise ValueError(f"guardian spec {spec!r} must look like 'package.module:Class'")
    obj = mod = import_user_module(module, f"guardian {spec!r}")
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise UserModuleError(
                f"guardian {spec!r}: module {module!r} (from {where(mod)}) has no attribute {attr!r}"
            ) from None
    return obj


def _builtin_available(name: str) -> bool:
    module = BUILTIN[name].partition(":")[0]
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a parent package is not there (a guardian not yet landed)
        return False


def available_guardians() -> list[str]:
    """Names accepted by :func:`make_guardian` (built-in and entry points)."""
    names = [n for n in BUILTIN if _builtin_available(n)]
    return names + sorted(n for n in _entry_points() if n not in names)


def load_guardian_class(name: str):
    if ":" in name:
        return _import(name)
    if name in BUILTIN and _builtin_available(name):
        return _import(BUILTIN[name])
    eps = _entry_points()
    if name in eps:
        return eps[name].load()
    raise ValueError(f"unknown guardian {name!r}; available: {available_guardians()} or 'module:Class'")


def accepts_argument(factory, name: str) -> bool:
    """Whether ``factory`` (a guardian class or callable, as the registry resolves it) takes a
    keyword argument ``name`` by that name.  A class's ``__init__`` that forwards ``**kwargs``
    is followed up its bases, so a subclass of a guardian that takes ``threads`` or ``env_id``
    takes it too; a bare ``**kwargs`` that reaches no named parameter does not count."""
    targets = (
        [c.__dict__["__init__"] for c in factory.__mro__ if "__init__" in c.__dict__ and c is not object]
        if isinstance(factory, type)
        else [factory]
    )
    for fn in targets:
        try:
            params = inspect.signature(fn).parameters
        except (TypeError, ValueError):  # a builtin without a signature
            return False
        p = params.get(name)
        if p is not None and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY):
            return True
        if not any(q.kind is q.VAR_KEYWORD for q in params.values()):
            return False
    return False


def make_guardian(name, env_id: str | None = None, **kwargs) -> Guardian:
    """Instantiate a guardian by registry name, entry-point name or ``module:Class``, or from the
    class (or factory) :func:`load_guardian_class` gave for one.

    ``env_id``: the env the guardian will serve, passed on as the guardian's ``env_id``
    argument when its constructor takes one by that name (the ``lrmm`` guardians pick their
    shipped model by it) and ignored otherwise."""
    cls = load_guardian_class(name) if isinstance(name, str) else name
    if env_id is not None and "env_id" not in kwargs and accepts_argument(cls, "env_id"):
        kwargs["env_id"] = env_id
    if inspect.isfunction(cls) or inspect.ismethod(cls):
        _check_factory(cls, kwargs)
    obj = cls(**kwargs) if isinstance(cls, type) else cls(**kwargs) if callable(cls) else cls
    if not hasattr(obj, "act") or not hasattr(obj, "reset"):
        raise TypeError(f"{name!r} did not produce a guardian (needs reset() and act()); got {type(obj).__name__}")
    return obj


def _check_factory(fn, kwargs: dict) -> None:
    """``TypeError`` saying what a ``module:attr`` naming a function must be when ``fn`` cannot be
    called with the guardian's options ``kwargs`` (a policy function ``fn(obs)``, most often)."""
    try:
        sig = inspect.signature(fn)
    except (TypeError, ValueError):  # no signature to check: the call says what is wrong
        return
    try:
        sig.bind(**kwargs)
    except TypeError as e:
        module = getattr(fn, "__module__", None) or "its module"
        label = f"{module}:{getattr(fn, '__qualname__', fn)}{sig}"
        options = ", ".join(f"{k}={v!r}" for k, v in kwargs.items()) or "none"
        raise TypeError(
            f"{label} is a function, not a Guardian class, and calling it with the guardian's options ({options}) "
            f"fails: {e}; a module:Class must name a Guardian subclass (or a factory taking the guardian's options "
            "as keywords and returning a guardian), and a policy function fn(obs) -> action is wrapped with "
            f"rmm_guardians.CallableGuardian, e.g. `def guardian(): return CallableGuardian({fn.__name__})` in "
            f"{module}, named {module}:guardian"
        ) from None
