"""Disturbances on many episodes at once, as the vector env's rows (:mod:`rmm_envs.disturbances`).

Row ``i`` of each function is what ``draws[i]`` (one episode's :class:`Realisation`) does at sim
time ``times[i]``, the same numbers whether one row or many are done at once, so a vector env's
sub-envs are the single env's.  A :class:`RowStreams` kept by the caller holds each row's current
block of every white-noise stream, so a step reads all rows' values with one gather rather than
asking each row's draw in turn; the values are the draws' own, bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from rmm_envs.disturbances.realisation import _BIAS, _NOISE, BLOCK, Realisation

__all__ = ["RowStreams", "control_rows", "observation_rows", "rate_rows"]


class RowStreams:
    """Each of ``n`` rows' current block of its draw's white streams (see the module docstring).

    The owner calls :meth:`forget` for a row when the row gets a new draw (at its reset)."""

    def __init__(self, n: int) -> None:
        self.n = int(n)
        self._held: dict[Any, np.ndarray] = {}  # stream -> (n,) the block each row holds (-1: none)
        self._values: dict[Any, np.ndarray] = {}  # stream -> (n, BLOCK, width) those blocks

    def forget(self, i) -> None:
        """Row(s) ``i`` hold nothing any more (they have new draws)."""
        for held in self._held.values():
            held[i] = -1

    def values(self, stream, draws: Sequence[Realisation], signal: Callable, rows: np.ndarray, ks: np.ndarray):
        """``(len(rows), width)``: row ``j`` is ``signal(draws[j]).at(ks[j])`` (a white stream),
        for the rows ``rows`` of this cache."""
        b, i = np.divmod(ks, BLOCK)
        held = self._held.get(stream)
        if held is None:
            held = self._held[stream] = np.full(self.n, -1, np.int64)
            self._values[stream] = np.empty((self.n, BLOCK, signal(draws[0]).n))
        values = self._values[stream]
        for j in np.flatnonzero(held[rows] != b).tolist():  # a new block: every BLOCK steps, or a new draw
            values[rows[j]] = signal(draws[j]).block(int(b[j]))
            held[rows[j]] = b[j]
        return values[rows, i]


def _signal_values(draws, signal, ks, streams: RowStreams | None, stream, rows) -> np.ndarray:
    """Every row's value of one signal (``signal(draw)``) at its step ``ks``."""
    if streams is not None and signal(draws[0]).shape == "white":
        return streams.values(stream, draws, signal, rows, ks)
    return np.stack([signal(d).at(int(k)) for d, k in zip(draws, ks, strict=True)])


def _steps(draws: Sequence[Realisation], times) -> np.ndarray:
    """Each row's step index (:meth:`Realisation.step_of`, all rows at once: the same numbers)."""
    return np.floor(np.asarray(times, dtype=np.float64) / draws[0].dt + 1e-9).astype(np.int64)


def _rows(rows, n: int) -> np.ndarray:
    """The cache's rows these ``n`` are: ``rows``, or all of them in order."""
    return np.arange(n) if rows is None else np.asarray(rows, dtype=np.int64)


def observation_rows(
    draws: Sequence[Realisation],
    obs: np.ndarray,
    times: Sequence[float],
    streams: RowStreams | None = None,
    rows=None,
) -> np.ndarray:
    """Observations ``(N, D)`` as the sensors of ``N`` episodes report them at sim times ``times``:
    row ``i`` is ``draws[i].observation(obs[i], times[i])``.  The draws share one list of
    disturbances; ``streams`` (optional) is the caller's cache, ``rows`` the rows of it these are
    (all, in order, by default)."""
    out = np.array(obs, dtype=np.float64)
    first = draws[0]
    if not first.senses:
        return out.astype(np.asarray(obs).dtype, copy=False)
    ks = _steps(draws, times)
    at = _rows(rows, len(draws))
    for j, (op, idx, level, _, hi) in enumerate(first._obs_ops):
        if op == _BIAS:
            out[:, idx] += level
            continue
        vals = _signal_values(draws, lambda d, j=j: d._obs_ops[j][3], ks, streams, ("obs", j), at)
        if op == _NOISE:
            out[:, idx] += level * vals
        else:  # a dropped ray reads its maximum: uniform in [0, 1) below the probability
            sub = out[:, idx]
            dropped = (vals + 1.0) * 0.5 < level
            assert hi is not None  # a dropout's maximum ranges, set with it
            sub[dropped] = np.broadcast_to(hi, sub.shape)[dropped]
            out[:, idx] = sub
    np.minimum(out, first._hi, out=out)
    np.maximum(out, first._lo, out=out)
    return out.astype(np.asarray(obs).dtype, copy=False)


def control_rows(
    draws: Sequence[Realisation],
    u: np.ndarray,
    times: Sequence[float],
    streams: RowStreams | None = None,
    rows=None,
) -> np.ndarray:
    """Controls ``(N, C)`` the plants of ``N`` episodes apply when ``u`` is commanded at ``times``:
    row ``i`` is ``draws[i].control(u[i], times[i])`` (see :meth:`Realisation.control`)."""
    out = np.array(u, dtype=np.float64)
    first = draws[0]
    if not first.actuates:
        return out
    ks = _steps(draws, times)
    at = _rows(rows, len(draws))
    if first._delay is not None:
        out = np.stack([d._delayed(out[i], int(k)) for i, (d, k) in enumerate(zip(draws, ks, strict=True))])
    for j in range(len(first._act_noise)):
        scale = first._act_noise[j][0]
        out = out + scale * _signal_values(draws, lambda d, j=j: d._act_noise[j][1], ks, streams, ("act", j), at)
    if any(d._gained for d in draws):
        out = out * np.stack([d.gain for d in draws])
    assert first._low is not None and first._high is not None  # support.check refused act kinds otherwise
    return np.minimum(np.maximum(out, first._low), first._high)


def rate_rows(
    draws: Sequence[Realisation],
    times: Sequence[float],
    dim: int,
    streams: RowStreams | None = None,
    rows=None,
) -> np.ndarray:
    """The additive state-rate disturbances ``(N, dim)`` of ``N`` episodes at ``times``: row ``i``
    is ``draws[i].rate(times[i], dim)``."""
    out = np.zeros((len(draws), dim))
    first = draws[0]
    if not first.pushes:
        return out
    ks = _steps(draws, times)
    at = _rows(rows, len(draws))
    for j, (idx, scale, _) in enumerate(first._rate_ops):
        out[:, idx] += scale * _signal_values(draws, lambda d, j=j: d._rate_ops[j][2], ks, streams, ("rate", j), at)
    return out
