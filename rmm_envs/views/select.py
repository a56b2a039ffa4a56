"""Which view shows an env: :func:`view_for`, from the ``view`` of the env's system's spec."""

from __future__ import annotations

from rmm_envs.catalog import load_ref, system_of_env
from rmm_envs.views.base import View
from rmm_envs.views.pole import EnvFrameView

__all__ = ["view_for"]


def _system_view(env):
    """The ``factory(env, size)`` of ``env``'s system (:attr:`rmm_envs.catalog.SystemSpec.view`),
    for its guarded envs and its simulator; ``None`` otherwise."""
    found = system_of_env(env)
    if found is None or found[1] == "plain" or found[0].view is None:
        return None
    return load_ref(found[0].view)


def view_for(env, size: int = 512) -> View:
    """The view of ``env`` (a gym env, wrapped or not): the one its system states
    (:func:`rmm_envs.catalog.system_of_env`); a guarded env of :mod:`rmm_envs.envs.any_env` whose
    system states none, by its simulator's system (``CartPole-v1`` guarded under an id of your
    own); otherwise the env's own ``rgb_array`` frame (:class:`EnvFrameView`, a ``ValueError``
    when it does not render)."""
    u = env.unwrapped
    factory = _system_view(env)
    if factory is None:
        inner = getattr(u, "env", None)  # GuardedAnyEnv.env: the simulator (a Gymnasium env)
        if inner is not None and getattr(u, "simulator", None) is None:
            factory = _system_view(inner)
    if factory is not None:
        return factory(env, size)
    return EnvFrameView(env, size)
