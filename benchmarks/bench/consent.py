"""What ``rmm-bench replay`` imports, and the files it must find unchanged, before it imports anything.

A database may come from someone else, and a stored run names the code it ran: a
``module:Class`` agent, a ``module:Id`` env, and any ``module:Name`` in the agent's or the env's
options (a strategy of one's own, ``lrmm.strategies="+mod:Cls"``), all found by
:func:`rmm_bench.config.run_modules`.  Replay imports such a module only with consent: the command
line names it (``--agent module:Class``, ``--env module:Id``, ``--trust-module module``) or says
``--trust-modules``; any other is refused in one line naming it and how to consent
(:func:`check_consent`), before anything is imported.  While the replay runs,
:func:`consented_imports` refuses any other module a user names indirectly (a strategy named in a
stored model file's decision) the same way.  Built-in guardians, envs and strategies (bare names)
need no consent.

The source file of each such module is one of the run's inputs (its SHA-256 keyed the run), so
a replay after the module was edited is refused naming the file (:func:`check_inputs`), never
replayed and blamed on non-determinism.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from rmm_bench.config import file_sha256, module_name, resolve_input, run_modules
from rmm_envs.user_modules import named_modules, only_consented

__all__ = ["check_consent", "check_inputs", "consented_imports", "named_on_command_line"]


def _module_of(name: str | None) -> str | None:
    module, colon, _ = (name or "").rpartition(":")
    return module if colon and module else None


def named_on_command_line(req) -> set[str]:
    """The modules a replay's command line names (``req``: a :class:`rmm_bench.replay.ReplayRequest`)."""
    return {m for m in (_module_of(req.agent), _module_of(req.env)) if m} | set(getattr(req, "trusted", ()) or ())


def check_consent(config: dict, req) -> None:
    """Refuse (``ValueError``, one line) a module the stored run ``config`` names that the command
    line does not, unless ``--trust-modules``."""
    if req.trust_modules:
        return
    named = named_on_command_line(req)
    for what, value in (("agent", config["agent"]), ("env", config["env_id"])):
        module = _module_of(value)
        if module and module not in named:
            raise ValueError(
                f"the stored {what} {value!r} is imported from module {module!r}, which only the database names; "
                f"a replay imports a module only when the command line names it: pass --{what} {value} "
                "(expected) or --trust-modules"
            )
    modules = run_modules(config["agent"], config["env_id"], config.get("agent_kwargs"), config.get("env_kwargs"))
    for module, where in modules.items():
        if module not in named:
            raise ValueError(
                f"the stored {where} imports module {module!r}, which only the database names; a replay imports "
                f"a module only when the command line names it: pass --trust-module {module} (expected) "
                "or --trust-modules"
            )


@contextlib.contextmanager
def consented_imports(req) -> Iterator[None]:
    """While a replay runs: a module a user names (``rmm_envs.user_modules.import_user_module``) is
    imported only if the command line named it, or with ``--trust-modules``."""
    allowed = None if req.trust_modules else named_on_command_line(req)
    hint = "the replay's command line does not name it: pass --trust-module {0} or --trust-modules"
    with only_consented(allowed, hint):
        yield


def module_sources(config: dict) -> set[str]:
    """The file names the modules the run names are read from (``pkg/mod.py``,
    ``pkg/mod/__init__.py``), as their stored ``inputs`` end."""
    names = {module_name(config.get("agent", "")), module_name(config.get("env_id", ""), env=True)}
    for options in (config.get("agent_kwargs"), config.get("env_kwargs")):
        names |= set(named_modules(options or {}))
    stems = [n.replace(".", os.sep) for n in names if n]
    return {s + ".py" for s in stems} | {os.path.join(s, "__init__.py") for s in stems}


def check_inputs(config: dict) -> None:
    """Every file the run read must still have the SHA-256 stored with the run.  A module's source
    file that is gone is left to its import, which names the module and why it cannot be imported."""
    sources = module_sources(config)
    for path, digest in (config.get("inputs") or {}).items():
        if not resolve_input(path).is_file():
            if any(path == s or path.endswith(os.sep + s) for s in sources):
                continue
            raise ValueError(f"{path}: the run read this file (sha256 {digest[:12]}...) and it no longer exists")
        now = file_sha256(resolve_input(path))
        if now != digest:
            raise ValueError(
                f"{path}: its sha256 is {now[:12]}..., expected {digest[:12]}... (the file the run read); "
                "replay needs the same file"
            )
