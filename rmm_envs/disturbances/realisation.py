"""One episode's draw of disturbances, a function of the episode seed and the sim-time step
(see :mod:`rmm_envs.disturbances`)."""

from __future__ import annotations

import math
import zlib
from collections import deque
from collections.abc import Sequence

import numpy as np

from rmm_envs.disturbances.spec import Disturbance, SystemSupport, kind_code
from rmm_envs.portable import norm

__all__ = ["BLOCK", "Realisation"]

#: steps drawn at once by a white-noise stream; values depend on the step, not on this size's use
BLOCK = 256
#: the streams' domain in the seed sequence (distinct from every other stream of the project)
_DOMAIN = 0x6469_7374  # "dist"


class _Signal:
    """``n`` components of one shape, a function of the step index only."""

    def __init__(self, shape: str, n: int, seq: np.random.SeedSequence, dt: float, horizon: float, gaussian: bool):
        self.shape, self.n, self.seq, self.gaussian = shape, n, seq, gaussian
        self._blocks: dict[int, np.ndarray] = {}
        rng = np.random.default_rng(np.random.SeedSequence(seq.entropy, spawn_key=(*seq.spawn_key, 0)))
        self.held = self._draw(rng, n)
        half = max(1, int(0.5 * horizon / dt))
        self.onset = int(rng.integers(0, half))
        self.period = float(rng.uniform(2.0, 10.0))
        self.phase = rng.uniform(0.0, 2 * np.pi, n)
        self.dt = dt

    def _draw(self, rng: np.random.Generator, *shape: int) -> np.ndarray:
        return rng.standard_normal(shape) if self.gaussian else rng.uniform(-1.0, 1.0, shape)

    def _white(self, k: int) -> np.ndarray:
        b, i = divmod(k, BLOCK)
        block = self._blocks.get(b)
        if block is None:
            seq = np.random.SeedSequence(self.seq.entropy, spawn_key=(*self.seq.spawn_key, 1, b))
            block = self._draw(np.random.default_rng(seq), BLOCK, self.n)
            if len(self._blocks) > 4:  # episodes move forward: keep the few latest blocks
                self._blocks.pop(min(self._blocks))
            self._blocks[b] = block
        return block[i]

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


class Realisation:
    """One episode's draw of ``disturbances`` on a system (:class:`SystemSupport`), from ``seed``.

    Every value is a function of the episode seed, the disturbance's kind and components, and the
    sim-time step, so the same episode gives the same realisation to every agent, and adding a
    disturbance of another kind leaves the others' draws as they were.
    """

    def __init__(self, disturbances: Sequence[Disturbance], support: SystemSupport, seed: int | Sequence[int]):
        support.check(disturbances)
        self.disturbances = tuple(disturbances)
        self.support = support
        self.dt = float(support.dt)
        self._signals: list[_Signal | None] = []
        self._masks: list[np.ndarray | None] = []
        seeds = (seed,) if isinstance(seed, (int, np.integer)) else tuple(seed)
        root = (*(int(x) & 0xFFFF_FFFF_FFFF_FFFF for x in seeds), _DOMAIN)
        n_act = 0 if support.action_low is None else int(np.size(support.action_low))
        size = int(getattr(support.layout, "size", 0))
        self._delay: deque | None = None  # (t, commanded) pairs, the oldest first
        self._delay_steps = 0
        self.gain = np.ones(n_act)
        self.parameters = dict(support.parameters)
        for d in self.disturbances:
            seq = np.random.SeedSequence(list(root), spawn_key=(kind_code(d.kind), zlib.crc32("+".join(d.on).encode())))
            mask: np.ndarray | None = None
            n = 0
            if d.target == "obs":
                mask = np.zeros(size, bool)
                names = d.on or (
                    ("rays",)
                    if d.kind in ("obs-bias", "ray-dropout")
                    else tuple(f for f in support.obs_fields() if f != "time")
                )
                for c in names:
                    mask[support.layout[c]] = True  # type: ignore[index]
                n = int(mask.sum())
            elif d.target == "act":
                n = n_act
            elif d.target == "rate":
                idx = [support.rates[c] for c in (d.on or tuple(support.rates))]
                mask = np.asarray(idx, int)
                n = len(idx)
            signal = None
            if d.kind in ("obs-noise", "act-noise", "dyn-rate", "impulse"):
                signal = _Signal(d.shape, n, seq, self.dt, support.horizon, gaussian=d.kind != "dyn-rate")
                if d.kind == "impulse":  # a push of the given size in a random direction
                    direction = signal.held / max(norm(signal.held), 1e-12)
                    signal.held = direction
            elif d.kind == "ray-dropout":
                signal = _Signal("white", n, seq, self.dt, support.horizon, gaussian=False)
            elif d.kind == "act-gain":
                rng = np.random.default_rng(seq)
                self.gain = self.gain * (1.0 + d.level * rng.uniform(-1.0, 1.0, n_act))
            elif d.kind == "act-delay":
                self._delay = deque()
                self._delay_steps = int(d.level)
            elif d.kind == "mismatch":
                for name in d.on or sorted(support.parameters):  # each parameter its own stream
                    own = np.random.SeedSequence(list(root), spawn_key=(kind_code(d.kind), zlib.crc32(name.encode())))
                    factor = 1.0 + d.level * np.random.default_rng(own).uniform(-1.0, 1.0)
                    self.parameters[name] = support.parameters[name] * factor
            self._signals.append(signal)
            self._masks.append(mask)

    def step_of(self, t: float) -> int:
        """The step index of sim time ``t``."""
        return int(math.floor(t / self.dt + 1e-9))

    def observation(self, obs: np.ndarray, t: float) -> np.ndarray:
        """``obs`` as the sensors report it at sim time ``t`` (a new array)."""
        out = np.array(obs, dtype=np.float64, copy=True)
        k = self.step_of(t)
        for d, sig, mask in zip(self.disturbances, self._signals, self._masks, strict=True):
            if d.target != "obs":
                continue
            assert mask is not None
            if d.kind == "obs-noise":
                assert sig is not None
                out[mask] += d.level * sig.at(k)
            elif d.kind == "obs-bias":
                out[mask] += d.level
            elif d.kind == "ray-dropout":
                assert sig is not None and self.support.obs_high is not None
                dropped = (sig.at(k) + 1.0) * 0.5 < d.level  # uniform in [0, 1) below p
                high = np.asarray(self.support.obs_high, float)[mask]
                vals = out[mask]
                vals[dropped] = high[dropped]
                out[mask] = vals
        if self.support.obs_high is not None:
            out = np.minimum(out, np.asarray(self.support.obs_high, float))
        if self.support.layout is not None and "rays" in self.support.obs_fields():
            rays = self.support.layout["rays"]  # type: ignore[index]
            out[rays] = np.maximum(out[rays], 0.0)  # a range is never negative
        return out.astype(np.asarray(obs).dtype, copy=False)

    def control(self, u: np.ndarray, t: float) -> np.ndarray:
        """The control the plant applies at sim time ``t`` when ``u`` is commanded (a new array),
        within the control's bounds.  Call it in order of sim time: a delay of ``k`` applies the
        latest control commanded at or before step ``floor(t / dt) - k`` (the first until then),
        whatever the number of calls in between."""
        low = np.asarray(self.support.action_low, float)
        high = np.asarray(self.support.action_high, float)
        out = np.array(u, dtype=np.float64, copy=True).reshape(-1)
        if self._delay is not None:  # the control commanded k steps of sim time before (the first until then)
            self._delay.append((self.step_of(t), out.copy()))
            due = self.step_of(t) - self._delay_steps
            while len(self._delay) > 1 and self._delay[1][0] <= due:
                self._delay.popleft()
            out = self._delay[0][1].copy()
        k = self.step_of(t)
        for d, sig in zip(self.disturbances, self._signals, strict=True):
            if d.kind == "act-noise":
                assert sig is not None
                out = out + d.level * 0.5 * (high - low) * sig.at(k)
        out = out * self.gain
        return np.clip(out, low, high)

    def rate(self, t: float, dim: int) -> np.ndarray:
        """The additive state-rate disturbance at sim time ``t`` (``(dim,)``; zero where none)."""
        out = np.zeros(dim)
        k = self.step_of(t)
        for d, sig, idx in zip(self.disturbances, self._signals, self._masks, strict=True):
            if d.target != "rate":
                continue
            assert sig is not None and idx is not None
            if d.kind == "impulse":  # a displacement of the given size over one step
                out[idx] += (d.level / self.dt) * sig.at(k)
            else:
                out[idx] += d.level * sig.at(k)
        return out

    @property
    def active(self) -> bool:
        return bool(self.disturbances)
