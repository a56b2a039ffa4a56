"""The options several ``rmm-bench`` subcommands share, as argparse parent parsers, and the old
spellings they refuse.

One flag, one meaning, in every subcommand (``tests/test_cli_flags.py`` walks every parser):

* ``DIR`` (positional, dest ``results_dir`` or ``results_dirs``): a results directory, a run's
  ``--out``, or its ``results.db`` (:func:`results_dir`);
* ``--agent``: which agents, one or a comma list (:func:`agent_option`);
* ``--out``: a directory that a command writes into; a single file a command writes has a flag
  named for what it holds (``--table``, ``--png``, ``--html``, ``--video``);
* ``--seed``: the master seed that the episodes' seeds derive from; other seeds are named for
  what they seed (``--bootstrap-seed``, ``--world-seed``);
* ``--env-opt KEY=JSON``: an env constructor argument, repeatable (:func:`env_opt_option`,
  :func:`parse_env_opts`).

An old spelling (:func:`refuse`) is refused with one line naming the new one, rather than
accepted silently: nothing is released yet, so a script that still says ``--agents`` is told.
"""

from __future__ import annotations

import argparse
import json

from rmm_envs.disturbances import parse_disturbances

__all__ = [
    "RenamedOption",
    "agent_option",
    "disturb_option",
    "disturbance_opts",
    "env_opt_option",
    "out_dir_option",
    "parse_env_opts",
    "refuse",
    "results_dir",
]


class RenamedOption(ValueError):
    """An old spelling of a flag: ``rmm-bench`` prints the message as one line and exits 2."""


class _Refused(argparse.Action):
    """A flag that was renamed or retired: raises :class:`RenamedOption` when given (argparse
    itself would print the usage before the message; this is one line)."""

    def __init__(self, option_strings, dest, hint: str = "", **kwargs):
        kwargs.update(nargs="?", default=argparse.SUPPRESS, help=argparse.SUPPRESS)
        super().__init__(option_strings, dest, **kwargs)
        self.hint = hint

    def __call__(self, parser, namespace, values, option_string=None):
        raise RenamedOption(f"{option_string} is no longer accepted; {self.hint}")


def refuse(p: argparse.ArgumentParser, flag: str, hint: str) -> None:
    """Refuse ``flag`` in ``p`` with one line ending in ``hint`` (e.g. ``"use --agent"``)."""
    p.add_argument(flag, action=_Refused, hint=hint)


def results_dir(several: bool = False) -> argparse.ArgumentParser:
    """The positional results directory: ``DIR`` (``results_dir``), or ``DIR [DIR ...]`` (``results_dirs``)."""
    p = argparse.ArgumentParser(add_help=False)
    if several:
        p.add_argument(
            "results_dirs", nargs="+", metavar="DIR", help="results directories (a run's --out) or their results.db"
        )
    else:
        p.add_argument("results_dir", metavar="DIR", help="a results directory (a run's --out) or its results.db")
    return p


def agent_option(help: str, default: str | None = None, required: bool = False) -> argparse.ArgumentParser:
    """``--agent``: one agent or a comma list; ``--agents`` refused."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--agent", default=default, required=required, help=help)
    refuse(p, "--agents", "use --agent (one agent or a comma list)")
    return p


def out_dir_option(default, help: str, type=None) -> argparse.ArgumentParser:
    """``--out DIR``: the directory a command writes into."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--out", default=default, type=type, metavar="DIR", help=help)
    return p


def env_opt_option() -> argparse.ArgumentParser:
    """``--env-opt KEY=JSON`` (repeatable); ``--env-kwargs`` refused."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument(
        "--env-opt",
        action="append",
        default=[],
        metavar="KEY=JSON",
        help="an argument of the env's constructor, its value as JSON (a string in quotes), e.g. "
        "maze_kind='\"mixed\"'; repeatable",
    )
    refuse(p, "--env-kwargs", "use --env-opt KEY=JSON, once per argument")
    return p


def disturb_option() -> argparse.ArgumentParser:
    """``--disturb KIND[.COMPONENTS]=LEVEL[@SHAPE]`` (repeatable): the env's ``disturbances``."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument(
        "--disturb",
        action="append",
        default=[],
        metavar="KIND=LEVEL",
        help="a disturbance of the env, e.g. obs-noise.rays=0.2, act-delay=2, dyn-rate=0.1@white, mismatch=0.2 "
        "(docs/disturbances.md); repeatable; shorthand for --env-opt disturbances=[...]",
    )
    return p


def disturbance_opts(items: list[str] | None, env_opts: dict, accepted: set[str] | None, env_id: str) -> dict:
    """The env option ``disturbances`` from ``--disturb`` items (or as ``--env-opt`` gave it), in
    one canonical form (sorted strings, so the run's identity does not depend on the order given);
    ``{}`` when none.  ValueError, in one line, for a bad item, both spellings at once, or an env
    that takes no disturbances."""
    given = env_opts.get("disturbances")
    if items and given is not None:
        raise ValueError("give disturbances with --disturb or with --env-opt disturbances=..., not both")
    spec = list(items) if items else given
    found = parse_disturbances(spec)
    if not found:
        return {}
    if accepted is not None and "disturbances" not in accepted:
        raise ValueError(f"--disturb {found[0]}: {env_id} takes no disturbances (docs/disturbances.md lists the envs)")
    return {"disturbances": sorted(str(d) for d in found)}


def parse_env_opts(items: list[str] | None, accepted: set[str] | None = None, env_id: str = "") -> dict:
    """``--env-opt KEY=JSON`` values as a dict.  ValueError, in one line naming the bad item, for
    an item without ``=``, a value that is not JSON, a key given twice, or (``accepted`` given: the
    constructor's arguments) a key the env ``env_id`` does not take."""
    opts: dict = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ValueError(f"--env-opt {item!r}: expected KEY=JSON, e.g. maze_kind='\"mixed\"'")
        if key in opts:
            raise ValueError(f"--env-opt {item!r}: {key} is given twice; give each argument once")
        try:
            opts[key] = json.loads(value)
        except json.JSONDecodeError:
            raise ValueError(f"--env-opt {item!r}: the value {value!r} is not JSON (a string needs quotes)") from None
        if accepted is not None and key not in accepted:
            takes = ", ".join(sorted(accepted)) or "none"
            raise ValueError(f"--env-opt {item!r}: {env_id} takes no argument {key!r}; it takes: {takes}")
    return opts
