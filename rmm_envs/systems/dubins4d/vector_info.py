"""The end-of-episode entries of :class:`rmm_envs.systems.dubins4d.vector.Dubins4DCirclesVectorEnv`'s
``info``: each sub-env's outcome and the single env's episode statistics, as masked arrays."""

from __future__ import annotations

import numpy as np

from rmm_envs.envs.guarded import EPISODE_KEY

__all__ = ["ended_info", "reset_info"]


def ended_info(env, ended: np.ndarray, collision: np.ndarray, goal: np.ndarray) -> dict:
    """``outcome`` and ``episode`` (the single env's ``episode_statistics``) of the sub-envs
    where ``ended``, as arrays with masks (zero or ``None`` elsewhere, as Gymnasium fills)."""
    n_steps = env._n_steps
    with np.errstate(divide="ignore", invalid="ignore"):
        avg = np.where(n_steps > 0, env._cum_compute / n_steps, 0.0)
    outcome = np.full(env.num_envs, None, dtype=object)
    for i in np.nonzero(ended)[0]:
        outcome[i] = "collision" if collision[i] else "goal" if goal[i] else "timeout"
    masks = np.repeat(ended[None], 12, axis=0)  # one independent mask row per key
    episode = {"outcome": outcome.copy(), "_outcome": masks[0]}
    for j, (key, value) in enumerate(
        (
            ("n_env_steps", n_steps),
            ("n_active_ctrl_env_steps", env._n_active),
            ("active_ctrl_sim_time", env._active_time),
            ("cum_sim_time", env._sim_time),
            ("cum_compute_time", env._cum_compute),
            ("avg_compute_time", avg),
            ("cum_reward", env._cum_reward),
            ("cum_cost", env._cum_cost),
            ("final_speed", env._states[:, 3]),
        ),
        start=1,
    ):
        episode[key] = np.where(ended, value, value.dtype.type(0))
        episode[f"_{key}"] = masks[j]
    return {"outcome": outcome, "_outcome": masks[10], EPISODE_KEY: episode, f"_{EPISODE_KEY}": masks[11]}


def _masked(value: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """A copy of ``value`` (``(N, ...)``) with the rows outside ``mask`` zero (``None`` for objects)."""
    out = np.zeros_like(value) if value.dtype != object else np.full(value.shape, None, dtype=object)
    out[mask] = value[mask]
    return out


def reset_info(env, idx: np.ndarray) -> dict:
    mask = np.zeros(env.num_envs, dtype=bool)
    mask[idx] = True
    sim_time = np.zeros(env.num_envs)
    state = np.zeros((env.num_envs, 4))
    state[idx] = env._states[idx]
    nominal = np.zeros((env.num_envs, 2))
    nominal[idx] = env._nominal[idx]
    return {
        "sim_time": sim_time,
        "_sim_time": mask,
        "state": state,
        "_state": mask.copy(),
        "nominal_control": nominal,
        "_nominal_control": mask.copy(),
    }
