"""What an episode's row holds and how an error reads in it: the contract's statistics and the
store's columns (which are results, which timings), the episode's end as a row, and an error's
one-line message with its innermost frames (see :mod:`rmm_bench.runner`)."""

from __future__ import annotations

import traceback
from typing import Any

from rmm_envs.envs.guarded import EPISODE_KEY

__all__ = [
    "CACHE_STATS",
    "CLOCK_COLUMNS",
    "EPISODE_STATISTICS",
    "OPTIONAL_STATISTICS",
    "REPRODUCIBLE_CLOCKS",
    "TIMING_COLUMNS",
    "TRACEBACK_CHARS",
    "EnvContractError",
    "EpisodeTimeout",
    "is_timing_stat",
]

#: The store's columns read from ``info["episode_stats"]`` on the step that ends an episode (the
#: parallel-autonomy contract), column -> statistic.  Every env offering the contract reports these.
EPISODE_STATISTICS = {
    "steps": "n_env_steps",
    "active_steps": "n_active_ctrl_env_steps",
    "sim_time": "cum_sim_time",
    "active_sim_time": "active_ctrl_sim_time",
    "compute_time": "cum_compute_time",
    "avg_compute_time": "avg_compute_time",
    "cum_reward": "cum_reward",
}
#: Statistics an env may report (NULL in the store when it does not): ``final_speed`` (a vehicle's
#: speed) and ``cum_cost`` (the episode's summed ``info["cost"]``, Safety-Gymnasium's safety cost).
OPTIONAL_STATISTICS = {"final_speed": "final_speed", "cost": "cum_cost"}


#: Columns that measure time on the machine that ran the episode (wall time, the guardian's
#: decision and setup times, when it finished): never results, never compared by a replay.
TIMING_COLUMNS = frozenset(
    {"decision_mean", "decision_std", "decision_max", "precompute_time", "wall_time", "finished"}
)
#: Columns that sum the env clock's laps: results when the clock is reproduced (a fixed clock, or
#: a clocked run replayed from its trace), timings otherwise (a blocking env under a wall clock).
CLOCK_COLUMNS = frozenset({"compute_time", "avg_compute_time"})
#: Clock modes (:attr:`rmm_envs.clocks.Clock.mode`) whose laps need no trace: the run's options give them.
REPRODUCIBLE_CLOCKS = frozenset({"fixed", "replay", "manual"})


#: Guardian statistics that count this machine's state rather than the episode: whether a value
#: function came from the on-disk cache or was solved (``hj``'s ``cache_hits``, ``solves``).  A
#: replay on a warm cache hits where the run solved, deciding the same.
CACHE_STATS = frozenset({"cache_hits", "solves"})


def is_timing_stat(key: str) -> bool:
    """Whether a guardian statistic (a key of ``guardian_stats``) is a timing column, not a result:
    its name ends in ``_seconds`` (``hj``'s ``solve_seconds``), or it is one of :data:`CACHE_STATS`.
    The one rule for every guardian: a third-party guardian names a timing statistic so, and
    replay leaves it out of the comparison."""
    return key.endswith("_seconds") or key in CACHE_STATS


class EpisodeTimeout(Exception):
    pass


class EnvContractError(RuntimeError):
    """The env ended an episode without the statistics of the parallel-autonomy contract."""


def _statistics(env_id: str, info: dict) -> dict:
    """The store's columns from the last step's ``info`` (the contract's ``outcome`` and ``episode_stats``)."""
    ep: dict[str, Any] = info.get(EPISODE_KEY, {})  # read only when info holds it
    missing = [k for k in ("outcome", EPISODE_KEY) if k not in info] or [
        k for k in EPISODE_STATISTICS.values() if k not in ep
    ]
    if missing:
        where = "info" if EPISODE_KEY not in info or "outcome" not in info else f'info["{EPISODE_KEY}"]'
        raise EnvContractError(
            f"env {env_id} ended an episode without {where} keys {missing} (the parallel-autonomy "
            f"contract: info['outcome'] and info['{EPISODE_KEY}'] with "
            f"{sorted(EPISODE_STATISTICS.values())})"
        )
    out = {col: ep[k] for col, k in EPISODE_STATISTICS.items()}
    out.update({col: ep.get(k) for col, k in OPTIONAL_STATISTICS.items()})
    return {"outcome": info["outcome"], **out}


#: characters of an error's traceback kept in the store (after its one-line message, at most 500)
TRACEBACK_CHARS = 1500


def _traceback_text(e: BaseException, budget: int = TRACEBACK_CHARS) -> str:
    """``e``'s traceback in at most ``budget`` characters, keeping its innermost frames (where the
    code that raised is: a guardian's, or an env's driver deep under Gymnasium's wrappers) and
    leaving out the outermost ones that do not fit, said in one line."""
    header = "Traceback (most recent call last):\n"
    last = "".join(traceback.format_exception_only(type(e), e))[-300:]
    frames = traceback.format_tb(e.__traceback__)
    kept: list[str] = []
    room = budget - len(header) - len(last) - 60  # 60: the line saying how many frames were left out
    for frame in reversed(frames):
        if len(frame) > room:
            if not kept:  # the innermost frame always shows, its end (the line that raised) first
                kept.append("  ..." + frame[-max(room - 6, 0) :])
            break
        kept.append(frame)
        room -= len(frame)
    kept.reverse()
    skipped = len(frames) - len(kept)
    left_out = f"  ... {skipped} outer frame{'' if skipped == 1 else 's'} left out\n" if skipped else ""
    return (header + left_out + "".join(kept) + last)[-budget:]


def _error_text(e: BaseException, where: str = "") -> str:
    """The store's ``error``: ``Type: message`` on the first line (what reports and replays
    compare), then ``where`` (e.g. which env call raised), then the traceback's innermost frames."""
    return (
        f"{type(e).__name__}: {e}"[:500]
        + (f"\n{where}" if where else "")
        + ("" if isinstance(e, EpisodeTimeout) else "\n" + _traceback_text(e))
    )
