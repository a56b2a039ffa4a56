"""The env and the guardian of a replay: :func:`build_env` rebuilds the run's env with its stored
options (a clocked run's clock a :class:`~rmm_envs.clocks.ReplayClock`), :func:`drawable_env`
makes it drawable for ``--video``/``--frames``, :func:`check_guardian` imports and builds the
run's guardian as the episode will, refusing in one line what cannot be.
"""

from __future__ import annotations

import os

import gymnasium as gym

from rmm_bench.config import EpisodeTask, InputChanged, changed_inputs, run_input_digests
from rmm_bench.replay_plan import ReplayTarget
from rmm_bench.runner import guardian_for
from rmm_envs.clocks import ReplayClock
from rmm_envs.env_plugins import EnvUnavailable, resolve_env_id
from rmm_envs.user_modules import search_user_folders
from rmm_envs.views import view_for

__all__ = ["build_env", "check_guardian", "drawable_env"]


def build_env(target: ReplayTarget, render_mode: str | None = None):
    """The env the run's episodes ran on, built with the run's options; a clocked run's clock is a
    :class:`~rmm_envs.clocks.ReplayClock` (loaded per episode).  ``render_mode``: also passed to
    the env (to draw it).  ValueError when it cannot be made."""
    search_user_folders((os.getcwd(),))  # a module:Id env's module, after the installed packages
    kwargs = dict(target.run.env_kwargs)
    if target.clock_trace is not None:
        kwargs["clock"] = ReplayClock((), "no episode yet")
    if render_mode is not None:
        kwargs["render_mode"] = render_mode
    try:
        return gym.make(resolve_env_id(target.run.env_id), **kwargs)
    except EnvUnavailable as e:
        raise ValueError(f"{e}; expected the env the run used to be importable") from None
    except Exception as e:  # noqa: BLE001 - its constructor failed: the stored options no longer build it
        raise ValueError(
            f"--env {target.run.env_id}: the run's env cannot be made with its stored options {target.run.env_kwargs}: "
            f"{type(e).__name__}: {e}"
        ) from None


def drawable_env(target: ReplayTarget, env, size: int):
    """``env`` ready to be drawn: as it is when a view of the package draws it, else rebuilt with
    ``render_mode="rgb_array"`` (its own frames: a simulator of your own, a Gymnasium env);
    ``ValueError`` naming the env, never the guardian, when it cannot draw at all."""
    try:
        view_for(env, size)
        return env
    except ValueError:
        pass
    try:
        drawn = build_env(target, render_mode="rgb_array")
        view_for(drawn, size)
    except Exception as e:  # noqa: BLE001 - the env cannot render: it is the cause, not the guardian
        raise ValueError(
            f"--video/--frames: {target.run.env_id} cannot draw its episodes: it has no view in this package "
            f"and does not render with render_mode='rgb_array' ({e}); replay without --video/--frames "
            "verifies it"
        ) from None
    env.close()
    return drawn


def check_guardian(target: ReplayTarget) -> None:
    """Import and build the run's guardian (as the episode will), refused in one line if it cannot be."""
    task = EpisodeTask(run=target.run, run_key=target.run_key, episode=0, seed=0, import_path=(os.getcwd(),))
    try:
        guardian = guardian_for(task)
    except InputChanged as e:
        raise ValueError(f"{e}".split(": a file changed")[0] + ": expected the file the run read") from None
    except Exception as e:  # noqa: BLE001 - an import or a constructor that fails now
        raise ValueError(
            f"--agent {target.run.agent}: the run's guardian cannot be imported or built now: {type(e).__name__}: {e}"
        ) from None
    changed = changed_inputs(target.run.inputs, run_input_digests(guardian, target.run))
    if changed:
        raise ValueError(f"{changed}: expected the files the run read")
