"""Whether a replayed episode is the stored one: :func:`replay_episode` re-simulates it through the
runner's own episode function and :func:`compare_rows` compares every stored result column.

Floats are compared bit for bit as the store reads them back (:func:`_as_stored`), ``nan`` equal
to ``nan``; timing columns never, the clock's compute time only when the clock is reproduced
(fixed, or a wall clock played back from its trace).  A difference is reported with the first
differing column and both values, and the note that a guardian reading the time itself or not
deterministic cannot be verified.
"""

from __future__ import annotations

import json
import math
import os
import sqlite3

from rmm_bench.config import EpisodeTask
from rmm_bench.replay_plan import ReplayTarget
from rmm_bench.runner import CLOCK_COLUMNS, REPRODUCIBLE_CLOCKS, TIMING_COLUMNS, is_timing_stat, play_episode
from rmm_bench.store import EPISODE_FIELDS
from rmm_envs.clocks import TraceExhausted

__all__ = ["compare_rows", "replay_episode"]

#: The columns compared, in this order (the rest of the row follows in the store's order).
_FIRST = ("outcome", "error_kind", "steps", "sim_time", "active_steps", "active_sim_time", "final_speed", "cost")
#: Columns naming the episode, not results of it.
_IDENTITY = ("run_key", "episode", "agent", "seed")
_UNVERIFIABLE = (
    "(a guardian that reads the time itself or is not deterministic cannot be verified: "
    "docs/getting-started.md, Replaying an episode)"
)


def _as_stored(result) -> dict:
    """``result`` as the store would read it back: through an in-memory table of the same columns."""
    con = sqlite3.connect(":memory:")
    try:
        keys = list(EPISODE_FIELDS)
        con.execute(f"CREATE TABLE episodes ({', '.join(f'{k} {v}' for k, v in EPISODE_FIELDS.items())})")
        row = result.as_row()
        con.execute(f"INSERT INTO episodes VALUES ({', '.join('?' * len(keys))})", [row[k] for k in keys])
        cur = con.execute("SELECT * FROM episodes")
        return dict(zip([d[0] for d in cur.description], cur.fetchone(), strict=True))
    finally:
        con.close()


def _same(a, b) -> bool:
    """Equal as stored: floats bit for bit (``nan`` equal to ``nan``)."""
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def compare_rows(stored: dict, replayed: dict, clock_reproduced: bool) -> tuple[str, object, object] | None:
    """The first result column where ``replayed`` differs from ``stored`` (both as the store
    reads them): ``(column, stored value, replayed value)``, or None when every one is equal.
    Only columns the stored row has are compared (an older layout lacks some); timing columns
    never, the clock columns only when ``clock_reproduced``; ``guardian_stats`` key by key
    (``guardian_stats.KEY``), its timings aside; an error by its first line."""
    skip = set(_IDENTITY) | TIMING_COLUMNS | (set() if clock_reproduced else CLOCK_COLUMNS)
    order = [c for c in _FIRST if c in stored] + [c for c in stored if c not in _FIRST]
    for col in order:
        if col in skip:
            continue
        a, b = stored[col], replayed.get(col)
        if col == "start" and a is None:  # a row stored before starts were fingerprinted
            continue
        if col == "guardian_stats":
            sa, sb = json.loads(a or "{}"), json.loads(b or "{}")
            for k in sorted(set(sa) | set(sb)):
                if not is_timing_stat(k) and not _same(sa.get(k), sb.get(k)):
                    return f"guardian_stats.{k}", sa.get(k), sb.get(k)
            continue
        if col == "error":
            a = (a or "").splitlines()[0] if a else a
            b = (b or "").splitlines()[0] if b else b
        if not _same(a, b):
            return col, a, b
    return None


def replay_episode(target: ReplayTarget, env=None, drawing=None) -> tuple[str, bool]:
    """Re-simulate ``target``'s episode and compare it with its row: ``(message, verified)``.

    ``env``: one built for the run by :func:`build_env` (reused across episodes of one run);
    ``drawing``: a :class:`rmm_bench.video.EpisodeDrawing` that records the episode's frames."""
    row = target.row
    i = row["episode"]
    label = f"episode {i} of {target.run.agent}'s run {target.run_key}"
    clock = None
    if target.clock_trace is not None:
        clock = env.get_wrapper_attr("clock")
        clock.load(target.clock_trace, label)
    task = EpisodeTask(
        run=target.run, run_key=target.run_key, episode=i, seed=int(row["seed"]), import_path=(os.getcwd(),)
    )
    record = play_episode(task, env, observer=drawing)
    replayed = _as_stored(record.result)
    error = replayed.get("error") or ""
    first = error.splitlines()[0] if error else ""
    if first.startswith(TraceExhausted.__name__):
        return (f"episode {i}: differs: {first} {_UNVERIFIABLE}", False)
    reproduced = target.clock_mode in REPRODUCIBLE_CLOCKS or target.clock_trace is not None
    diff = compare_rows(row, replayed, reproduced)
    where = ""
    if replayed["outcome"] == "error":
        where = "; the replay raised: " + " | ".join(line.strip() for line in error.splitlines()[-3:] if line.strip())
    if diff is not None:
        col, a, b = diff
        return (f"episode {i}: differs in {col}: stored {a!r}, replayed {b!r} {_UNVERIFIABLE}{where}", False)
    if clock is not None and clock.used != len(clock.laps):
        return (
            f"episode {i}: differs in the clock trace: the replay read {clock.used} of its {len(clock.laps)} laps "
            f"{_UNVERIFIABLE}",
            False,
        )
    return (f"episode {i}: verified{where}", True)
