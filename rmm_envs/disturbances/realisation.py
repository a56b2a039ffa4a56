"""One episode's draw of disturbances, a function of the episode seed and the sim-time step
(see :mod:`rmm_envs.disturbances`)."""

from __future__ import annotations

import math
import zlib
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from rmm_envs.disturbances.spec import Disturbance, SystemSupport, kind_code
from rmm_envs.machine_independent import norm

__all__ = ["BLOCK", "Plan", "Realisation"]

#: steps drawn at once by a white-noise stream; values depend on the step, not on this size's use
BLOCK = 256
#: the streams' domain in the seed sequence (distinct from every other stream of the project)
_DOMAIN = 0x6469_7374  # "dist"


class _Signal:
    """``n`` components of one shape, a function of the step index only."""

    def __init__(self, shape: str, n: int, seq: np.random.SeedSequence, dt: float, horizon: float, gaussian: bool):
        self.shape, self.n, self.seq, self.gaussian = shape, n, seq, gaussian
        self._blocks: dict[int, np.ndarray] = {}
        self.dt = dt
        if shape == "white":  # nothing held: each block of steps is drawn when first needed
            return
        rng = np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, 0)))
        self.held = self._draw(rng, n)
        half = max(1, int(0.5 * horizon / dt))
        self.onset = int(rng.integers(0, half))
        self.period = float(rng.uniform(2.0, 10.0))
        self.phase = rng.uniform(0.0, 2 * np.pi, n)

    def _draw(self, rng: np.random.Generator, *shape: int) -> np.ndarray:
        return rng.standard_normal(shape) if self.gaussian else rng.uniform(-1.0, 1.0, shape)

    def block(self, b: int) -> np.ndarray:
        """A white stream's values at steps ``b * BLOCK ... (b + 1) * BLOCK - 1`` (``(BLOCK, n)``)."""
        block = self._blocks.get(b)
        if block is None:
            seq = np.random.SeedSequence(self.seq.entropy, spawn_key=(*self.seq.spawn_key, 1, b))
            block = self._draw(np.random.default_rng(seq), BLOCK, self.n)
            if len(self._blocks) > 4:  # episodes move forward: keep the few latest blocks
                self._blocks.pop(min(self._blocks))
            self._blocks[b] = block
        return block

    def _white(self, k: int) -> np.ndarray:
        b, i = divmod(k, BLOCK)
        return self.block(b)[i]

    def at(self, k: int) -> np.ndarray:
        """The unit-level value at step ``k`` (``(n,)``)."""
        if self.shape == "white":
            return self._white(k)
        if self.shape == "uniform":
            return self.held
        if self.shape == "step":
            return self.held if k >= self.onset else np.zeros(self.n)
        if self.shape == "impulse":
            return self.held if k == self.onset else np.zeros(self.n)
        if self.shape == "periodic":
            return self.held * np.sin(2 * np.pi * k * self.dt / self.period + self.phase)
        raise AssertionError(self.shape)


_NOISE, _BIAS, _DROP = 0, 1, 2  # the observation's operations


class Plan:
    """What ``disturbances`` do on a system (:class:`SystemSupport`), worked out once: the fields,
    indices, scales and bounds each operation touches and the seed-sequence key of each stream.
    An env makes one when it is made; each episode's :class:`Realisation` only draws."""

    def __init__(self, disturbances: Sequence[Disturbance], support: SystemSupport):
        support.check(disturbances)
        self.disturbances = tuple(disturbances)
        self.support = support
        self.dt = float(support.dt)
        self.n_act = 0 if support.action_low is None else int(np.size(support.action_low))
        size = int(getattr(support.layout, "size", 0))
        high = None if support.obs_high is None else np.asarray(support.obs_high, float)
        self.low = None if support.action_low is None else np.asarray(support.action_low, float)
        self.high = None if support.action_high is None else np.asarray(support.action_high, float)
        # (operation, fields, level, how many, maxima for a dropout, stream key, shape)
        self.obs_ops: list[tuple[int, Any, float, int, np.ndarray | None, tuple[int, int], str]] = []
        self.act_noise: list[tuple[np.ndarray, tuple[int, int], str]] = []
        self.gains: list[tuple[float, tuple[int, int]]] = []
        self.delay_steps: int | None = None
        # (components, scale, stream key, shape, an impulse)
        self.rate_ops: list[tuple[np.ndarray, float, tuple[int, int], str, bool]] = []
        self.mismatch: list[tuple[str, float, tuple[int, int]]] = []
        touched = np.zeros(size, bool)
        for d in self.disturbances:
            key = (kind_code(d.kind), zlib.crc32("+".join(d.on).encode()))
            if d.target == "obs":
                mask = np.zeros(size, bool)
                default = ("rays",) if d.kind in ("obs-bias", "ray-dropout") else support.obs_fields()
                for c in d.on or tuple(f for f in default if f != "time"):
                    mask[support.layout[c]] = True  # type: ignore[index]
                idx = np.flatnonzero(mask)
                touched |= mask
                op = {"obs-noise": _NOISE, "obs-bias": _BIAS, "ray-dropout": _DROP}[d.kind]
                hi = high[idx] if op == _DROP and high is not None else None
                self.obs_ops.append((op, _as_slice(idx), d.level, idx.size, hi, key, d.shape))
            elif d.kind == "act-noise":
                assert self.low is not None and self.high is not None  # support.check refused it otherwise
                self.act_noise.append((d.level * 0.5 * (self.high - self.low), key, d.shape))
            elif d.kind == "act-gain":
                self.gains.append((d.level, key))
            elif d.kind == "act-delay":
                self.delay_steps = int(d.level)
            elif d.target == "rate":
                ridx = np.asarray([support.rates[c] for c in (d.on or tuple(support.rates))], int)
                impulse = d.kind == "impulse"  # a push of the given size over one step
                self.rate_ops.append((ridx, d.level / self.dt if impulse else d.level, key, d.shape, impulse))
            elif d.kind == "mismatch":
                for name in d.on or sorted(support.parameters):  # each parameter its own stream
                    self.mismatch.append((name, d.level, (kind_code(d.kind), zlib.crc32(name.encode()))))
        # after the operations: each touched field back within its bounds, a range never negative
        self.obs_hi = np.full(size, np.inf)  # untouched fields: no bound (min with inf keeps them)
        if high is not None:
            self.obs_hi[touched] = high[touched]
        self.obs_lo = np.full(size, -np.inf)
        if "rays" in support.obs_fields():
            rays = np.zeros(size, bool)
            rays[support.layout["rays"]] = True  # type: ignore[index]
            self.obs_lo[rays & touched] = 0.0

    @property
    def moves_plant(self) -> bool:
        """Whether these disturbances act on the plant (its control, its rates or its parameters),
        not only on the sensors."""
        return bool(self.act_noise or self.gains or self.delay_steps is not None or self.rate_ops or self.mismatch)


class Realisation:
    """One episode's draw of ``disturbances`` on a system (:class:`SystemSupport`), from ``seed``.

    Every value is a function of the episode seed, the disturbance's kind and components, and the
    sim-time step, so the same episode gives the same realisation to every agent, and adding a
    disturbance of another kind leaves the others' draws as they were.  ``plan``: the
    :class:`Plan` of these disturbances on this support, when the caller keeps one (an env does).
    """

    def __init__(
        self,
        disturbances: Sequence[Disturbance],
        support: SystemSupport,
        seed: int | Sequence[int],
        plan: Plan | None = None,
    ):
        plan = plan if plan is not None else Plan(disturbances, support)
        self.plan = plan
        self.disturbances = plan.disturbances
        self.support = support
        self.dt = plan.dt
        seeds = (seed,) if isinstance(seed, (int, np.integer)) else tuple(seed)
        root = [*(int(x) & 0xFFFF_FFFF_FFFF_FFFF for x in seeds), _DOMAIN]
        horizon = float(support.horizon)

        def stream(key: tuple[int, int]) -> np.random.SeedSequence:
            return np.random.SeedSequence(root, spawn_key=key)

        self._obs_ops: list[tuple[int, Any, float, _Signal | None, np.ndarray | None]] = []
        for op, idx, level, n, hi, key, shape in plan.obs_ops:
            sig = None
            if op != _BIAS:
                sig = _Signal(shape if op == _NOISE else "white", n, stream(key), self.dt, horizon, op == _NOISE)
            self._obs_ops.append((op, idx, level, sig, hi))
        self._act_noise = [
            (scale, _Signal(shape, plan.n_act, stream(key), self.dt, horizon, True))
            for scale, key, shape in plan.act_noise
        ]
        self.gain = np.ones(plan.n_act)
        for level, key in plan.gains:
            self.gain = self.gain * (1.0 + level * np.random.default_rng(stream(key)).uniform(-1.0, 1.0, plan.n_act))
        self._delay: deque | None = None if plan.delay_steps is None else deque()  # (step, commanded), oldest first
        self._delay_steps = plan.delay_steps or 0
        self._rate_ops: list[tuple[np.ndarray, float, _Signal]] = []
        for ridx, scale, key, shape, impulse in plan.rate_ops:
            sig = _Signal(shape, ridx.size, stream(key), self.dt, horizon, False)
            if impulse:  # in a random direction
                sig.held = sig.held / max(norm(sig.held), 1e-12)
            self._rate_ops.append((ridx, scale, sig))
        self.parameters = dict(support.parameters)
        for name, level, key in plan.mismatch:
            factor = 1.0 + level * np.random.default_rng(stream(key)).uniform(-1.0, 1.0)
            self.parameters[name] = support.parameters[name] * factor
        self._low, self._high = plan.low, plan.high
        self._hi, self._lo = plan.obs_hi, plan.obs_lo
        self._gained = bool(np.any(self.gain != 1.0))
        self.senses = bool(self._obs_ops)  #: whether the observation is disturbed
        self.actuates = bool(self._act_noise) or self._gained or self._delay is not None  #: the control
        self.pushes = bool(self._rate_ops)  #: the state's rates

    def step_of(self, t: float) -> int:
        """The step index of sim time ``t``."""
        return int(math.floor(t / self.dt + 1e-9))

    def observation(self, obs: np.ndarray, t: float) -> np.ndarray:
        """``obs`` as the sensors report it at sim time ``t`` (a new array): the numbers of
        :func:`rmm_envs.disturbances.rows.observation_rows` for one row, without stacking rows."""
        out = np.asarray(obs).astype(np.float64)
        if not self.senses:
            return out.astype(np.asarray(obs).dtype, copy=False)
        k = self.step_of(t)
        for op, idx, level, sig, hi in self._obs_ops:
            if op == _BIAS:
                out[idx] += level
            elif op == _NOISE:
                out[idx] += level * sig.at(k)  # type: ignore[union-attr]
            else:
                sub = out[idx]
                dropped = (sig.at(k) + 1.0) * 0.5 < level  # type: ignore[union-attr]
                sub[dropped] = hi[dropped]  # type: ignore[index]
                out[idx] = sub
        np.minimum(out, self._hi, out=out)
        np.maximum(out, self._lo, out=out)
        return out.astype(np.asarray(obs).dtype, copy=False)

    def control(self, u: np.ndarray, t: float) -> np.ndarray:
        """The control the plant applies at sim time ``t`` when ``u`` is commanded (a new array),
        within the control's bounds.  Call it in order of sim time: a delay of ``k`` applies the
        latest control commanded at or before step ``floor(t / dt) - k`` (the first until then),
        whatever the number of calls in between."""
        out = np.array(u, dtype=np.float64).reshape(-1)  # control_rows' arithmetic on one row
        if not self.actuates:
            return out
        k = self.step_of(t)
        if self._delay is not None:
            out = self._delayed(out, k)
        for scale, sig in self._act_noise:
            out = out + scale * sig.at(k)
        if self._gained:
            out = out * self.gain
        assert self._low is not None and self._high is not None  # support.check refused act kinds otherwise
        return np.minimum(np.maximum(out, self._low), self._high)

    def _delayed(self, u: np.ndarray, k: int) -> np.ndarray:
        assert self._delay is not None
        self._delay.append((k, u.copy()))
        due = k - self._delay_steps
        while len(self._delay) > 1 and self._delay[1][0] <= due:
            self._delay.popleft()
        return self._delay[0][1]

    def rate(self, t: float, dim: int) -> np.ndarray:
        """The additive state-rate disturbance at sim time ``t`` (``(dim,)``; zero where none)."""
        out = np.zeros(dim)  # rate_rows' arithmetic on one row
        if self.pushes:
            k = self.step_of(t)
            for idx, scale, sig in self._rate_ops:
                out[idx] += scale * sig.at(k)
        return out

    @property
    def active(self) -> bool:
        return bool(self.disturbances)


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """``idx`` (sorted, distinct) as a slice when it is a run of consecutive indices."""
    if idx.size and int(idx[-1]) - int(idx[0]) == idx.size - 1:
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx
