"""Stopwatches that measure a guardian's thinking time for non-blocking stepping.

A clock here is a stopwatch: ``start()`` marks the moment the environment hands the
observation to the agent, ``elapsed()`` reads the seconds since, when the agent's next action
arrives.  The environment turns that into simulated time (``elapsed * time_accel + base_step``).

* :class:`WallClock` (default): real monotonic time (the paper's mode); :class:`CPUClock`: the
  process's CPU time; :class:`FixedLatencyClock`: every decision takes ``latency`` seconds
  (reproducible); :class:`ManualClock`: a test double; :class:`ReplayClock`: plays back a
  stored clock trace, one lap per ``elapsed()`` (:class:`TraceExhausted` past its end).

``make_clock("wall" | "cpu" | "fixed:MS")`` builds one from a string (``MS`` in milliseconds).
"""

from __future__ import annotations

import math
import time

__all__ = [
    "CLOCK_FORMS",
    "CPUClock",
    "Clock",
    "FixedLatencyClock",
    "ManualClock",
    "ReplayClock",
    "TraceExhausted",
    "WallClock",
    "make_clock",
]


class Clock:
    """Base stopwatch. Subclasses define :meth:`now`; ``mode`` names the clock's mode for records."""

    mode = "abstract"

    def __init__(self) -> None:
        self._t0 = self.now()

    def now(self) -> float:  # pragma: no cover - abstract
        raise NotImplementedError

    def start(self) -> None:
        self._t0 = self.now()

    def elapsed(self) -> float:
        return max(0.0, self.now() - self._t0)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class WallClock(Clock):
    mode = "wall"

    def now(self) -> float:
        return time.perf_counter()


class CPUClock(Clock):
    mode = "cpu"

    def now(self) -> float:
        return time.process_time()


class FixedLatencyClock(Clock):
    """Every interval lasts exactly ``latency`` seconds, whatever really happened."""

    mode = "fixed"

    def __init__(self, latency: float = 0.0) -> None:
        latency = float(latency)
        if not latency >= 0 or latency == float("inf"):
            raise ValueError(f"latency must be a finite number of seconds >= 0, got {latency}")
        self.latency = latency
        super().__init__()

    def now(self) -> float:
        return 0.0

    def elapsed(self) -> float:
        return self.latency

    def __repr__(self) -> str:
        return f"FixedLatencyClock(latency={self.latency!r})"


class ManualClock(Clock):
    """A clock that moves only through :meth:`advance` (for tests)."""

    mode = "manual"

    def __init__(self, t: float = 0.0) -> None:
        self.t = float(t)
        super().__init__()

    def now(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        if dt < 0:
            raise ValueError(f"time cannot go backwards (dt={dt})")
        self.t += float(dt)


class TraceExhausted(RuntimeError):
    """A :class:`ReplayClock` was asked for more laps than its trace holds: the replay went on
    longer than the run it plays back (it diverged from it)."""


class ReplayClock(Clock):
    """Plays back a clock trace: the ``i``-th :meth:`elapsed` returns ``laps[i]`` exactly (the
    float64 a run's clock returned), whatever really happened; :meth:`start` marks nothing.

    Args:
        laps: the values, in the order the run read them.
        episode: what the trace belongs to, for messages (e.g. ``"episode 17 of run 3f2a..."``).

    Asked for a value past the end, it raises :class:`TraceExhausted` naming ``episode``.
    ``used`` counts the values returned so far (a replay that ends early leaves some unused)."""

    mode = "replay"

    def __init__(self, laps, episode: str = "the episode") -> None:
        self.load(laps, episode)
        super().__init__()

    def load(self, laps, episode: str = "the episode") -> None:
        """Play ``laps`` (of ``episode``) from their first on: one clock serves episode after episode."""
        self.laps = tuple(float(x) for x in laps)
        self.episode = str(episode)
        self.used = 0

    def now(self) -> float:
        return 0.0

    def start(self) -> None:
        pass

    def elapsed(self) -> float:
        if self.used >= len(self.laps):
            raise TraceExhausted(
                f"the clock trace of {self.episode} ran out: it holds {len(self.laps)} laps and the replay asked "
                f"for lap {self.used + 1}, so the replay went on longer than the run it plays back"
            )
        lap = self.laps[self.used]
        self.used += 1
        return lap

    def __repr__(self) -> str:
        return f"ReplayClock({len(self.laps)} laps, {self.episode})"


#: The forms :func:`make_clock` accepts, for error messages.
CLOCK_FORMS = "'wall', 'cpu' or 'fixed:MS' (MS a number of milliseconds >= 0, e.g. 'fixed:2')"


def make_clock(spec: str | Clock | None) -> Clock:
    """``None`` or ``"wall"`` -> :class:`WallClock`; ``"cpu"``; ``"fixed:MS"``; or a Clock.

    Parsed strictly (case and surrounding spaces aside): anything else, ``"fixed"`` without
    ``:MS``, ``"fixed2"`` or ``"fixed=2"`` included, raises ``ValueError`` naming the value and
    the accepted forms, so a mistyped clock never runs as another one."""
    if spec is None:
        return WallClock()
    if isinstance(spec, Clock):
        return spec
    if not isinstance(spec, str):
        raise TypeError(f"clock must be a Clock or a string, got {type(spec).__name__}")
    s = spec.strip().lower()
    if s == "wall":
        return WallClock()
    if s == "cpu":
        return CPUClock()
    mode, colon, ms = s.partition(":")
    if mode == "fixed" and colon:
        try:
            latency_ms = float(ms)
        except ValueError:
            latency_ms = math.nan
        if math.isfinite(latency_ms) and latency_ms >= 0:
            return FixedLatencyClock(latency_ms / 1000.0)
    raise ValueError(f"unknown clock {spec!r}; expected {CLOCK_FORMS}")
