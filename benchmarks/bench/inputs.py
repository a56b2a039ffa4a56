"""The files a run reads, by their SHA-256: what keys a run besides its options (``runs.config``'s ``inputs``).

* :func:`input_digests`: every file a guardian or an env reads (a string option naming a file,
  the files a guardian reports, e.g. a shipped model), named portably for the project's own
  (:func:`portable_path`, :func:`resolve_input`).
* :func:`source_digests`: the source file of each module of the user's own a run names
  (:func:`run_modules`: a ``module:Class`` agent, a ``module:Id`` env, a ``module:Name`` in the
  options such as a strategy of one's own), so editing it starts a new run; runs of built-in
  names have none, so their keys never change.
* :func:`changed_inputs` / :class:`InputChanged`: a file that no longer has the bytes the run
  was keyed with.

:func:`rmm_bench.config.run_input_digests` takes both of a run (it reads the run's configuration).

Re-exported by :mod:`rmm_bench.config`, where the rest of the harness imports them from.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
from pathlib import Path

from rmm_envs.user_modules import find_module_spec, named_modules

__all__ = [
    "PROJECT_PACKAGES",
    "InputChanged",
    "changed_inputs",
    "file_sha256",
    "input_digests",
    "module_name",
    "portable_path",
    "resolve_input",
    "run_modules",
    "source_digests",
]


def file_sha256(path: str | Path) -> str:
    """SHA-256 (hex) of the bytes of the file ``path``, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _strings(value):
    if isinstance(value, str):
        yield value
    elif isinstance(value, dict):
        for v in value.values():
            yield from _strings(v)
    elif isinstance(value, (list, tuple)):
        for v in value:
            yield from _strings(v)


def input_digests(guardian, *options: dict) -> dict[str, str]:
    """Every file a run reads, path -> SHA-256 of its bytes: each string option (of the guardian
    or the env) naming a regular file, and the files the guardian reports it read
    (:meth:`rmm_guardians.base.Guardian.input_files`, e.g. a shipped model)."""
    out: dict[str, str] = {}
    for opts in options:
        for text in _strings(opts):
            try:
                if len(text) < 4096 and Path(text).is_file():
                    out[text] = file_sha256(text)
            except (OSError, ValueError):  # unreadable or not a path: the guardian or env reports it when it reads it
                continue
    reported = getattr(guardian, "input_files", None)
    if callable(reported):
        out.update({str(k): str(v) for k, v in reported().items()})
    return dict(sorted((portable_path(k), v) for k, v in out.items()))


#: the project's packages: a file inside one is named by its place in the package
PROJECT_PACKAGES = ("rmm_envs", "rmm_guardians", "rmm_bench")


def _package_dir(name: str) -> Path | None:
    spec = importlib.util.find_spec(name)
    origin = spec.origin if spec is not None else None
    return Path(origin).resolve().parent if origin else None


def portable_path(path: str) -> str:
    """A file inside one of the project's installed packages (a shipped model) as
    ``package/relative/path``, the same on every machine and checkout, so the same run has the
    same key wherever it runs; any other path as given."""
    try:
        full = Path(path).resolve()
    except (OSError, RuntimeError):
        return path
    for name in PROJECT_PACKAGES:
        root = _package_dir(name)
        if root is not None and full.is_relative_to(root):
            return f"{name}/{full.relative_to(root).as_posix()}"
    return path


def resolve_input(key: str) -> Path:
    """The file an ``inputs`` key names on this machine: the inverse of :func:`portable_path`."""
    head, _, rest = key.partition("/")
    if head in PROJECT_PACKAGES and rest and not Path(key).is_absolute():
        root = _package_dir(head)
        if root is not None:
            return root / rest
    return Path(key)


def module_name(spec: str, env: bool = False) -> str | None:
    """The module of a ``module:Class`` agent (``env=False``) or a ``module:Id`` env id, as the
    registry and :func:`rmm_envs.env_plugins.resolve_env_id` split them; None for a bare name
    (a built-in guardian or env, an entry point)."""
    module, colon, rest = spec.rpartition(":") if env else spec.partition(":")
    return module if colon and module and rest else None


def _module_file(name: str) -> str | None:
    """The file module ``name`` is (or would be) loaded from: its own ``.py`` file, a package's
    ``__init__.py``; None for a namespace package, a built-in module or one not found."""
    mod = sys.modules.get(name)
    origin = getattr(mod, "__file__", None) if mod is not None else None
    if origin is None and mod is None:
        spec = find_module_spec(name)  # also in the user's folders (rmm_envs.user_modules.user_folders)
        origin = spec.origin if spec is not None and spec.has_location else None
    return origin if isinstance(origin, str) and os.path.isfile(origin) else None


def _path_key(path: str, base: str | None) -> str:
    """``path`` relative to ``base`` (default: the current directory) when it lies under it, so a
    project moved or cloned elsewhere keeps its run keys; else absolute."""
    full = os.path.abspath(path)
    try:
        rel = os.path.relpath(full, base or os.getcwd())
    except ValueError:  # another drive
        return full
    return full if rel == os.pardir or rel.startswith(os.pardir + os.sep) else rel


def run_modules(agent: str, env_id: str, agent_kwargs=None, env_kwargs=None) -> dict[str, str]:
    """Every module a run names, module -> what names it: the module of a ``module:Class`` agent,
    of a ``module:Id`` env, and of each ``module:Name`` in the agent's or the env's options (a
    strategy of one's own, ``lrmm.strategies="+mod:Cls"``: :func:`rmm_envs.user_modules.named_modules`);
    none for a run of built-in names.  What a replay imports only with consent, and whose
    sources key the run (:func:`source_digests`)."""
    out: dict[str, str] = {}
    named = [(module_name(agent), f"agent {agent!r}"), (module_name(env_id, env=True), f"env {env_id!r}")]
    for whose, options in (("agent", agent_kwargs), ("env", env_kwargs)):
        named += [(m, f"{whose} option {text!r}") for m, text in named_modules(options or {}).items()]
    for module, where in named:
        if module:
            out.setdefault(module, where)
    return out


def source_digests(
    agent: str, env_id: str, base: str | None = None, agent_kwargs=None, env_kwargs=None
) -> dict[str, str]:
    """The source files of the user's own code a run imports, path -> SHA-256: the module of a
    ``module:Class`` agent, of a ``module:Id`` env and of each ``module:Name`` in the agent's
    and the env's options (:func:`run_modules`; its own ``.py`` file, a package's
    ``__init__.py``), so editing it starts a new run.  Files that module imports are not
    covered.  Built-in guardians, envs and strategies (bare names) have none: their run keys
    are unchanged.  The module must be imported already (or importable); one that is not gives
    no entry (the import reports it).  ``base``: the folder paths are relative to (the directory
    ``rmm-bench`` ran in; default, the current one)."""
    out: dict[str, str] = {}
    for name in run_modules(agent, env_id, agent_kwargs, env_kwargs):
        path = _module_file(name) if name else None
        if path is not None:
            try:
                out[_path_key(path, base)] = file_sha256(path)
            except OSError:  # unreadable now: the run's check names it as unreadable
                continue
    return out


class InputChanged(RuntimeError):
    """A file the run reads no longer has the bytes the run was started with."""


def changed_inputs(recorded: dict[str, str], now: dict[str, str]) -> str:
    """'' if every file of ``recorded`` still has its digest in ``now``, else one clause per changed file."""
    return "; ".join(
        f"{path} (sha256 {digest[:12]}... when the run was keyed, "
        f"{now[path][:12] + '...' if now.get(path) else 'unreadable'} now)"
        for path, digest in recorded.items()
        if now.get(path) != digest
    )
