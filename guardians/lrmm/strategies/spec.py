"""Strategies by name (:data:`STRATEGIES`) and spec strings (:func:`parse_strategies`), the form
a command line and a model file's stored decision give them in."""

from __future__ import annotations

import ast

from rmm_envs.user_modules import import_user_module
from rmm_guardians.lrmm.strategies.base import Strategy
from rmm_guardians.lrmm.strategies.candidates import Restart, SafestCandidate
from rmm_guardians.lrmm.strategies.driver import RatedDriver, Slide
from rmm_guardians.lrmm.strategies.rays import BrakeTurn, RayTurn
from rmm_guardians.lrmm.strategies.timing import Commit, MovingAverage

__all__ = ["STRATEGIES", "parse_item", "parse_strategies", "spec_items", "split_spec", "strategy_specs"]

#: The built-in strategies by name.
STRATEGIES: dict[str, type[Strategy]] = {
    c.__name__: c for c in (SafestCandidate, Restart, BrakeTurn, RayTurn, RatedDriver, Slide, MovingAverage, Commit)
}


def _strategy_class(name: str) -> type[Strategy]:
    if ":" in name:
        module, _, attr = name.partition(":")
        if not module or not attr:
            raise ValueError(f"strategy {name!r} must look like 'package.module:Class'")
        # a module of one's own: found in the folder rmm-bench runs in, after the installed
        # packages, and refused by a replay the command line did not consent to
        mod = import_user_module(module, f"unknown strategy {name!r}")
        try:
            cls = getattr(mod, attr)
        except AttributeError as e:
            raise ValueError(f"unknown strategy {name!r}: {e}") from None
        if not (isinstance(cls, type) and issubclass(cls, Strategy)):
            raise ValueError(f"strategy {name!r} is not a subclass of rmm_guardians.lrmm.strategies.Strategy")
        return cls
    if name not in STRATEGIES:
        raise ValueError(f"unknown strategy {name!r}; the strategies are: {', '.join(STRATEGIES)} or 'module:Class'")
    return STRATEGIES[name]


def split_spec(text: str) -> list[str]:
    """``text`` split at the commas outside parentheses, items stripped, empty ones dropped."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if ch == "," and depth == 0:
            items.append(text[start:i])
            start = i + 1
    items.append(text[start:])
    return [s.strip() for s in items if s.strip()]


def parse_item(item: str) -> Strategy:
    """One strategy from one spec item (``"Commit(steps=18)"``, ``"Slide"``, ``"pkg.mod:Cls(1)"``);
    arguments must be literals.  A ``ValueError`` names a bad name or argument."""
    name, paren, rest = item.partition("(")
    name = name.strip()
    if not paren:
        return _strategy_class(name)()
    try:
        call = ast.parse(f"f({rest}", mode="eval").body
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == "f"):
            raise ValueError  # e.g. Commit()(3): a call of a call
        if any(isinstance(a, ast.Starred) for a in call.args) or any(k.arg is None for k in call.keywords):
            raise ValueError  # *args, **kwargs
        args = [ast.literal_eval(a) for a in call.args]
        kwargs = {k.arg: ast.literal_eval(k.value) for k in call.keywords if k.arg is not None}
    except (SyntaxError, ValueError):
        raise ValueError(f"strategy {item!r}: arguments must be literals, as in Commit(steps=18)") from None
    cls = _strategy_class(name)
    try:
        return cls(*args, **kwargs)
    except TypeError as e:
        raise ValueError(f"strategy {item!r}: {e}; its parameters: {', '.join(cls.PARAMS) or 'none'}") from None


def spec_items(spec) -> tuple[list, bool]:
    """``spec``'s items (a string split at its top-level commas, a sequence's elements) and whether
    they edit the stored composition (every item a string starting with ``+`` or ``-``); a
    ``ValueError`` for another type, an item neither a string nor a :class:`Strategy`, or a mix."""
    if not isinstance(spec, (str, list, tuple)):
        raise ValueError(f"strategies must be a spec string or a sequence of strategies, got {spec!r}")
    items: list = split_spec(spec) if isinstance(spec, str) else list(spec)
    if any(not isinstance(s, (str, Strategy)) for s in items):
        raise ValueError(f"strategies must be Strategy objects or spec strings, got {spec!r}")
    n_edits = sum(isinstance(s, str) and s[:1] in "+-" for s in items)
    if n_edits and n_edits != len(items):
        raise ValueError(f"strategies {spec!r}: either every item edits the stored ones (+/-) or none does")
    return items, n_edits > 0


def parse_strategies(spec, stored: tuple[Strategy, ...] = ()) -> tuple[Strategy, ...]:
    """Strategies from ``spec``: a sequence of :class:`Strategy` objects or spec strings, or one
    string of comma-separated items such as ``"SafestCandidate, Commit(steps=18), Restart(0.3)"``
    (``""``: none, the core alone).  When every item starts with ``-`` or ``+``, they edit
    ``stored`` (the model's composition): ``-Commit`` removes the Commit, ``+Commit(5)`` replaces
    it in place (or appends one).  An unknown name or bad argument is a ``ValueError`` naming it."""
    items, edits = spec_items(spec)
    if not edits:
        out = tuple(s if isinstance(s, Strategy) else parse_item(s) for s in items)
    else:
        out = tuple(stored)
        for item in items:
            if item[0] == "-":  # removal names a class: nothing is built
                cls = _strategy_class(item[1:].partition("(")[0].strip())
                if not any(type(s) is cls for s in out):
                    have = ", ".join(s.name for s in out) or "none"
                    raise ValueError(f"strategy {item!r}: no {cls.__name__} to remove (the stored ones: {have})")
                out = tuple(s for s in out if type(s) is not cls)
                continue
            new = parse_item(item[1:].strip())
            at = [i for i, s in enumerate(out) if type(s) is type(new)]
            out = out[: at[0]] + (new,) + out[at[0] + 1 :] if at else (*out, new)
    names = [type(s) for s in out]
    if len(set(names)) != len(names):
        raise ValueError(f"strategies {spec!r}: each strategy may appear once")
    return out


def strategy_specs(strategies) -> list[str]:
    """The spec strings of ``strategies`` (as stored in a model file's decision)."""
    return [s.spec() for s in strategies]
