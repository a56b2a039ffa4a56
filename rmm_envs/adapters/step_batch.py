"""A simulator's ``step_batch`` hook driven over a tree level: the loops of
:class:`rmm_envs.adapters.SnapshotScene` for a simulator that steps many states at once.

Both loops step a level's live branches together, one ``step_batch`` call per env step, test each
new state once with the scene's ``state_failed``, and let a branch leave the batch at its first
failed step, as the step-by-step path (``set_state``, then ``step`` until one fails) stops it.
:func:`batched_paths` keeps every state (the scene's ``propagate``); :func:`batched_failed_ends`
keeps only whether each branch failed and where a live one ended (the scene's
``propagate_failed``, which the estimator runs a level through): no path array, and a batch is
compacted only before a step and only when something failed.  Every state a branch reaches is
the one ``step_batch`` returned for it, so both give the same bits as the step-by-step path when
``step_batch`` repeats ``step``'s arithmetic (tests/test_snapshot_batch.py).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from numba import njit

__all__ = ["batch_actions", "batched_failed_ends", "batched_paths", "step_batch_checked"]


def batch_actions(space, actions) -> np.ndarray:
    """``(N, a)`` env actions (as :func:`rmm_envs.adapters.base.env_actions` gives them) in the
    form ``step_batch`` takes: ``(N, 1)`` int64 for ``Discrete``, the ``Box``'s dtype otherwise."""
    actions = np.asarray(actions)
    if isinstance(space, gym.spaces.Discrete):
        return np.ascontiguousarray(actions[:, :1].astype(np.int64))
    return np.ascontiguousarray(actions.astype(space.dtype))


def step_batch_checked(scene, states: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scene.sim.step_batch(states, actions)`` as ``((N, d) float, (N,) bool)``; a result of
    another form is a one-line ``TypeError``/``ValueError`` naming the scene and the hook."""
    result = scene.sim.step_batch(states, actions)
    if not (isinstance(result, tuple) and len(result) == 2):
        raise TypeError(
            f"{scene.name}: step_batch(states, actions) must return (states (N, d), failed (N,) bool), "
            f"got {type(result).__name__}"
        )
    nxt, failed = np.asarray(result[0], dtype=float), np.asarray(result[1], dtype=bool)
    n = states.shape[0]
    if nxt.shape != (n, scene.state_dim) or failed.shape != (n,):
        raise ValueError(
            f"{scene.name}: step_batch on {n} states must return shapes ({n}, "
            f"{scene.state_dim}) and ({n},), got {nxt.shape} and {failed.shape}"
        )
    return nxt, failed


def batched_paths(scene, states, actions, k: int, check: bool):
    """``(out (N, k, d), step_failed (N, k), any_failed (N, k))``: every state of each branch
    (``NaN`` after its first failure), the failures ``step_batch`` reported and, with ``check``,
    those or a failed new state (:meth:`state_failed`, on the live states only)."""
    n = states.shape[0]
    out = np.full((n, k, scene.state_dim), np.nan)
    step_failed = np.zeros((n, k), dtype=bool)
    any_failed = np.zeros((n, k), dtype=bool)
    acts = batch_actions(scene.action_space, actions)
    live = np.arange(n)
    current = np.array(states, dtype=float)
    for j in range(k):
        if live.size == 0:
            break
        nxt, failed = step_batch_checked(scene, current, acts[live])
        out[live, j] = nxt
        step_failed[live, j] = failed
        if check:
            failed = failed | scene.state_failed(nxt)
            any_failed[live, j] = failed
        keep = ~failed
        live, current = live[keep], nxt[keep]
    return out, step_failed, any_failed


def _drop_failed(step_failed, state_failed, live, failed):  # pragma: no cover - compiled
    """Mark ``failed[live[i]]`` where the step or the new state ``i`` failed; return the
    positions of the others and their ``live`` entries, in order."""
    n = step_failed.shape[0]
    rows = np.empty(n, np.int64)
    live2 = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        if step_failed[i] or state_failed[i]:
            failed[live[i]] = True
        else:
            rows[kept] = i
            live2[kept] = live[i]
            kept += 1
    return rows[:kept], live2[:kept]


_drop_failed = njit(cache=True)(_drop_failed)


def _put_rows(out, rows, values):  # pragma: no cover - compiled
    """``out[rows] = values`` for ``(N, d)`` arrays (numpy's fancy assignment of rows is slow)."""
    for i in range(rows.shape[0]):
        for j in range(values.shape[1]):
            out[rows[i], j] = values[i, j]


_put_rows = njit(cache=True)(_put_rows)


def batched_failed_ends(scene, states, actions, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``(failed (N,) bool, ends (N, d))`` of branches held at env ``actions`` (as ``step_batch``
    takes them) for ``k`` env steps: whether any step failed (``step_batch`` said so, or the
    state after it fails by ``scene.state_failed``), and each live branch's last state (a failed
    branch's row is its start state or the state it failed in: nothing reads it).  The same bits
    as ``path_failed(propagate(...))`` and the paths' last points."""
    states = np.asarray(states, dtype=float)
    n = states.shape[0]
    failed = np.zeros(n, dtype=bool)
    if n == 0:
        return failed, states.copy()
    acts = np.ascontiguousarray(actions)
    live = np.arange(n)
    current = states.copy()  # step_batch may write into its input; the caller's states stay as they were
    for j in range(k):
        nxt, step_failed = step_batch_checked(scene, current, acts)
        rows, live_now = _drop_failed(step_failed, np.asarray(scene.state_failed(nxt), dtype=bool), live, failed)
        if j == k - 1 or not live_now.size:  # no step after this one: no batch to compact
            break
        if live_now.size < live.size:  # the next step's batch: the branches still live
            current, acts, live = nxt.take(rows, axis=0), acts.take(rows, axis=0), live_now
        else:  # a copy: step_batch may return an array it writes again
            current = nxt.copy()
    if live.size == n:
        return failed, nxt.copy()
    ends = states.copy()
    _put_rows(ends, live, np.ascontiguousarray(nxt))
    return failed, ends
