"""Envs of other packages: ``module:Id`` and the ``gymnasium.envs`` entry points.

:func:`resolve_env_id` (which ``rmm-bench`` calls in its own process and in every worker, local
or Ray, before making the env) gets an env this package does not ship registered:

``module:Id``
    Gymnasium's own syntax: ``module`` is imported (the current directory first) and must
    register ``Id``.
A package's entry point in the group ``gymnasium.envs``
    When the id is not registered, each entry point of the group is loaded once per process (a
    ``module:function`` value is then called, a bare ``module`` value registers on import).  An
    entry point that raises is named in the error of an id that stays unregistered.

An example declaration: :func:`resolve_env_id`.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Callable
from importlib.metadata import entry_points
from typing import Any

import gymnasium as gym

import rmm_envs  # noqa: F401  (the package's own envs register on import)
from rmm_envs.user_modules import UserModuleError, import_user_module, where

__all__ = ["ENTRY_POINT_GROUP", "EnvUnavailable", "describe_env_error", "load_env_plugins", "resolve_env_id"]

ENTRY_POINT_GROUP = "gymnasium.envs"

_LOADED: dict[str, str | None] = {}  # entry point value -> None (loaded) or the error it raised


class EnvUnavailable(ValueError):
    """An env id that cannot be registered in this process; the message names the id and the cause."""


def load_env_plugins() -> dict[str, str | None]:
    """Load every ``gymnasium.envs`` entry point not loaded yet in this process; returns each
    value's outcome so far (``None``: loaded, else the error it raised)."""
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.value in _LOADED:
            continue
        try:
            obj = ep.load()
            if ep.attr and callable(obj):
                obj()
            _LOADED[ep.value] = None
        except Exception as e:  # noqa: BLE001 - reported with the id that needed it
            _LOADED[ep.value] = f"{type(e).__name__}: {e}"
    return dict(_LOADED)


def resolve_env_id(env_id: str) -> str:
    """Register ``env_id`` in this process if it can be (see the module docstring) and return the
    id ``gym.make`` takes without importing anything (``Id`` of ``module:Id``).  Raises
    :class:`EnvUnavailable` naming the id and the cause otherwise.

    Entry points are how Gymnasium before 1.0 loaded other packages' envs: a package declaring
    ``[project.entry-points."gymnasium.envs"] my_envs = "my_envs.registration:register"`` works
    with a plain ``--env MyEnv-v0``."""
    if not isinstance(env_id, str) or not env_id:
        raise EnvUnavailable(f"an env id must be a non-empty string, got {env_id!r}")
    module, _, name = env_id.rpartition(":")
    if module:  # "module:Id", as gym.make takes it: the module registers the env on import
        try:
            mod = import_user_module(module, f"--env {env_id!r}")
        except UserModuleError as e:  # an import that fails in any way leaves the id unregistered
            raise EnvUnavailable(str(e)) from None
        if name not in gym.registry:
            raise EnvUnavailable(
                f"--env {env_id!r}: importing {module!r} (from {where(mod)}) registered no env {name!r}"
            )
        return name
    if env_id not in gym.registry:
        failed = {v: err for v, err in load_env_plugins().items() if err is not None}
        if env_id not in gym.registry:
            plugins = "; ".join(f"entry point {v!r} raised {err}" for v, err in failed.items())
            near = difflib.get_close_matches(env_id, list(gym.registry), n=1)
            raise EnvUnavailable(
                f"--env {env_id!r} is not a registered Gymnasium env"
                + (f" (did you mean {near[0]!r}?)" if near else "")
                + f"; this package registers {', '.join(rmm_envs.ENV_IDS)}; another package's env is "
                f"registered by importing it (--env module:Id) or by that package's '{ENTRY_POINT_GROUP}' "
                "entry point" + (f"; {plugins}" if plugins else "")
            )
    return env_id


#: what Gymnasium's ``make`` appends to an error raised by an env's constructor
_CREATOR_SUFFIX = re.compile(r" was raised from the environment creator for \S+ with kwargs \(.*\)$", re.DOTALL)


def _bench_option(key: str, value: Any) -> str:
    return f"--{key.replace('_', '-')} {value}"


def describe_env_error(
    e: BaseException, env_id: str, env_kwargs: dict, option: Callable[[str, Any], str] = _bench_option
) -> str:
    """One line for any exception ``e`` raised by building the env ``env_id`` with ``env_kwargs``
    (``gym.make(env_id, **env_kwargs)``), as the commands print it after their name:

    * ``"<option>: <the constructor's own message>"`` when the message names one of ``env_kwargs``
      (an argument such as ``clock``): ``option(key, value)`` says how the command's user gave it
      (default: ``--time-accel 2``, as ``rmm-bench`` takes it);
    * else ``"--env <id>: <ExceptionType>: <message>"`` (the env itself cannot be built).

    Gymnasium's suffix ``"... was raised from the environment creator for <id> with kwargs (...)"``
    is left out, and a message spread over several lines is joined into one."""
    message = _CREATOR_SUFFIX.sub("", str(e)).strip()
    message = " ".join(line.strip() for line in message.splitlines() if line.strip()) or "(no message)"
    for k in env_kwargs:
        if re.search(rf"\b{re.escape(k)}\b", message):
            return f"{option(k, env_kwargs[k])}: {message}"
    return f"--env {env_id}: {type(e).__name__}: {message}"
