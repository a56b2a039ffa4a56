"""The collision taxonomy of ``rmm-bench collisions`` (:mod:`rmm_bench.collisions`): the classes,
the alarm log a replay fills, and the rule that classifies one collision from it."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["AVOIDED", "CLASSES", "UNVERIFIED", "AlarmLog", "Selection", "Verdict", "classify", "onset", "versus_lead"]

#: The classes, in the order they are tested and shown.
CLASSES = ("doomed", "unseen", "failed manoeuvre", "released", "alarm ignored")
#: An episode whose replay did not verify (not classified).
UNVERIFIED = "not verified"
#: Outcomes of the ``--versus`` agent that count as avoiding the collision.
AVOIDED = ("goal", "timeout")


class AlarmLog:
    """The observer a replay passes to :func:`rmm_bench.runner.play_episode`: after every step,
    who was in control (``info["active"]``, else the env's active-step count), the step's end
    time (``info["sim_time"]``, else the env's statistics) and the guardian's ``alarm()``."""

    def __init__(self) -> None:
        self.env: Any = None
        self.times: list[float] = [0.0]
        self.active: list[bool] = []
        self.alarms: list[tuple[float, float] | None] = []
        self._counted = 0

    def begin(self, env) -> None:
        self.env, self.times, self.active, self.alarms, self._counted = env, [0.0], [], [], 0

    def step(self, info, guardian) -> None:
        hook = getattr(guardian, "alarm", None)
        pair = hook() if callable(hook) else None
        self.alarms.append(None if pair is None else (float(pair[0]), float(pair[1])))
        stats = None
        if "active" in info:
            active = bool(info["active"])
        else:
            stats = self.env.unwrapped.episode_statistics()
            n = int(stats["n_active_ctrl_env_steps"])
            active, self._counted = n > self._counted, n
        if "sim_time" in info:
            t = float(info["sim_time"])
        else:
            stats = stats or self.env.unwrapped.episode_statistics()
            t = float(stats["cum_sim_time"])
        self.active.append(active)
        self.times.append(t)


@dataclass(frozen=True)
class Verdict:
    """One collision, classified (times in simulated seconds; ``nan`` where not defined)."""

    episode: int
    seed: int
    cls: str
    doomed: bool | None
    steps: int
    impact_s: float
    signal: bool  # the guardian reported an alarm (else control stood for it)
    first_alarm_s: float  # when the decision that first raised the alarm was taken
    alarm_to_impact_s: float
    in_control_at_impact: bool
    peak_before: float  # the highest alarm value before the last steps (nan without a signal)
    threshold: float  # the alarm's threshold at that peak (else at impact)
    versus_outcome: str | None = None
    versus_control_lead_s: float = math.nan  # how long before this impact the other agent took control
    verified: bool = True  # every replay of the episode (its own, the --versus agent's) verified its row
    note: str = ""


def _up(pair: tuple[float, float] | None) -> bool:
    return pair is not None and pair[0] > pair[1]  # nan compares False: not up


def onset(raised: list[bool], start: int, stop: int) -> int | None:
    """The first step in ``[start, stop)`` with ``raised``, traced back to where its stretch of
    consecutive raised steps began (possibly before ``start``); ``None`` when none is raised."""
    first = next((k for k in range(start, min(stop, len(raised))) if raised[k]), None)
    while first is not None and first > 0 and raised[first - 1]:
        first -= 1
    return first


def classify(
    active: list[bool],
    alarms: list[tuple[float, float] | None],
    times: list[float],
    doomed: bool | None,
    last_steps: int,
    window: float | None = None,
) -> tuple[str, dict]:
    """The class of a collision from its steps (``active[k]``, ``alarms[k]``: step ``k``'s
    controller and its decision's alarm; ``times[k]``: when step ``k`` began, ``times[-1]``
    the impact) and its measures.

    The crossing that counts is the onset of the first alarm stretch (consecutive steps with
    the alarm up; without any alarm, in control) that is up within the ``window`` seconds
    before impact (``None``: the whole episode), traced back to where that stretch began: an
    alarm about an earlier danger that went down again is not this collision's.  It is in time
    when it comes before the last ``last_steps`` steps."""
    n = len(active)
    if n == 0 or len(alarms) != n or len(times) != n + 1:
        raise ValueError(f"a collision needs at least one step and one time more than steps, got {n}, {len(times)}")
    signal = any(a is not None for a in alarms)
    raised = [_up(a) for a in alarms] if signal else [bool(a) for a in active]
    start = 0 if window is None else next((k for k in range(n) if times[k] >= times[-1] - window), n - 1)
    first = onset(raised, start, n)
    cut = n - last_steps  # steps before this index are "in time"
    in_time = first is not None and first < cut
    values = [a for a in alarms[start : max(cut, start)] if a is not None and not math.isnan(a[0])]
    peak = max(values, key=lambda a: a[0]) if values else None
    at_impact = alarms[-1]
    measures = {
        "first": first,
        "first_alarm_s": times[first] if first is not None else math.nan,
        "alarm_to_impact_s": times[-1] - times[first] if first is not None else math.nan,
        "in_control_at_impact": bool(active[-1]),
        "signal": signal,
        "peak_before": peak[0] if peak else math.nan,
        "threshold": peak[1] if peak else (at_impact[1] if at_impact else math.nan),
    }
    if doomed:
        return "doomed", measures
    if not in_time:
        return "unseen", measures
    assert first is not None
    if active[-1]:
        return "failed manoeuvre", measures
    if any(active[first:]):
        return "released", measures
    return "alarm ignored", measures


def _verdict(row: dict, log: AlarmLog, doomed: bool | None, last_steps: int, window: float | None) -> Verdict:
    cls, m = classify(log.active, log.alarms, log.times, doomed, last_steps, window)
    return Verdict(
        episode=int(row["episode"]),
        seed=int(row["seed"]),
        cls=cls,
        doomed=doomed,
        steps=len(log.active),
        impact_s=log.times[-1],
        signal=m["signal"],
        first_alarm_s=m["first_alarm_s"],
        alarm_to_impact_s=m["alarm_to_impact_s"],
        in_control_at_impact=m["in_control_at_impact"],
        peak_before=m["peak_before"],
        threshold=m["threshold"],
    )


@dataclass
class Selection:
    agent: str
    run_key: str
    describe: str
    episodes: list[int]
    doomed: dict[int, bool | None]
    collisions: int  # the agent's collisions in the run (before --versus)
    versus: str | None = None
    versus_key: str | None = None
    versus_outcomes: dict[int, str] | None = None


def versus_lead(log: AlarmLog, impact: float, window: float | None) -> float:
    """How long before ``impact`` (the first agent's) the other agent's control stretch that is
    on within the window before it began (``nan``: not in control there)."""
    begin = 0.0 if window is None else impact - window
    steps = len(log.active)
    start = next((k for k in range(steps) if log.times[k] >= begin), steps)
    stop = next((k for k in range(steps) if log.times[k] >= impact), steps)
    k = onset(log.active, start, stop)
    return math.nan if k is None else impact - log.times[k]
