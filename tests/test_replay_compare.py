"""replay's comparison of a stored row with its replay (``compare_rows``, used by merge too),
column by column on hand-made rows: which columns count, in which order, and how floats, NaN,
guardian statistics and errors compare (tests/test_replay.py replays real episodes)."""

from __future__ import annotations

import json
import math

from rmm_bench.replay import _same, compare_rows


def _row(**changes) -> dict:
    row = {
        "run_key": "k1", "episode": 3, "agent": "lrmm", "seed": 77,
        "outcome": "goal", "error_kind": None, "steps": 120, "sim_time": 12.0, "active_steps": 4,
        "active_sim_time": 0.4, "final_speed": 0.5, "cost": 1.25, "start": "abcd", "error": None,
        "guardian_stats": json.dumps({"qp_fallbacks": 1, "solve_seconds": 0.5}),
        "decision_mean": 0.001, "decision_std": 0.0, "decision_max": 0.002, "precompute_time": 0.1,
        "wall_time": 3.0, "finished": 1.7e9, "compute_time": 0.12, "avg_compute_time": 0.001,
    }  # fmt: skip
    row.update(changes)
    return row


def test_equal_rows_are_the_same():
    assert compare_rows(_row(), _row(), True) is None and compare_rows(_row(), _row(), False) is None


def test_the_episodes_identity_and_timings_are_not_results():
    other = _row(run_key="k2", episode=9, agent="x", seed=1, decision_mean=5.0, decision_std=1.0, decision_max=9.0,
                 precompute_time=2.0, wall_time=99.0, finished=0.0)  # fmt: skip
    assert compare_rows(_row(), other, True) is None


def test_the_clock_columns_count_only_when_the_clock_is_reproduced():
    for col in ("compute_time", "avg_compute_time"):
        assert compare_rows(_row(), _row(**{col: 0.5}), True) == (col, _row()[col], 0.5)
        assert compare_rows(_row(), _row(**{col: 0.5}), False) is None


def test_the_first_difference_in_the_results_order():
    replayed = _row(cost=2.0, steps=121, outcome="collision", final_speed=0.0, start="ffff")
    assert compare_rows(_row(), replayed, True) == ("outcome", "goal", "collision")
    assert compare_rows(_row(), {**replayed, "outcome": "goal"}, True) == ("steps", 120, 121)
    assert compare_rows(_row(), {**replayed, "outcome": "goal", "steps": 120}, True) == ("final_speed", 0.5, 0.0)
    assert compare_rows(_row(), _row(cost=2.0, start="ffff"), True) == ("cost", 1.25, 2.0)
    assert compare_rows(_row(), _row(start="ffff"), True) == ("start", "abcd", "ffff")
    assert compare_rows(_row(), _row(error_kind="guardian"), True) == ("error_kind", None, "guardian")


def test_floats_bit_for_bit_and_nan_equal_to_nan():
    assert compare_rows(_row(), _row(sim_time=12.000000000000002), True) == ("sim_time", 12.0, 12.000000000000002)
    assert compare_rows(_row(final_speed=math.nan), _row(final_speed=math.nan), True) is None
    assert compare_rows(_row(final_speed=math.nan), _row(final_speed=0.0), True)[0] == "final_speed"
    assert compare_rows(_row(final_speed=0.0), _row(final_speed=math.nan), True)[0] == "final_speed"
    assert _same(math.nan, math.nan) and _same(1.0, 1.0) and _same("a", "a") and _same(None, None)
    assert not _same(math.nan, 1.0) and not _same(1.0, math.nan) and not _same(math.nan, "nan")
    assert not _same(math.nan, None) and not _same(0.0, None)


def test_only_the_stored_rows_columns_are_compared():
    old = {k: v for k, v in _row().items() if k not in ("cost", "active_sim_time")}  # an older layout
    assert compare_rows(old, _row(cost=9.0, active_sim_time=9.0), True) is None
    # a column the replay lacks is a difference (None)
    replayed = {k: v for k, v in _row().items() if k != "final_speed"}
    assert compare_rows(_row(), replayed, True) == ("final_speed", 0.5, None)
    # a column outside the usual order is compared too
    assert compare_rows(_row(extra=1), _row(extra=2), True) == ("extra", 1, 2)


def test_a_start_stored_before_fingerprints_is_not_compared():
    assert compare_rows(_row(start=None), _row(start="abcd"), True) is None
    assert compare_rows(_row(start="abcd"), _row(start=None), True) == ("start", "abcd", None)


def test_guardian_statistics_key_by_key_timings_aside():
    stats = {"qp_fallbacks": 1, "solve_seconds": 0.5, "value_cache_hits": 3}
    assert compare_rows(_row(guardian_stats=json.dumps(stats)), _row(guardian_stats=json.dumps(stats)), True) is None
    timing = {**stats, "solve_seconds": 9.0}
    assert compare_rows(_row(guardian_stats=json.dumps(stats)), _row(guardian_stats=json.dumps(timing)), True) is None
    changed = {**stats, "qp_fallbacks": 2}
    assert compare_rows(_row(guardian_stats=json.dumps(stats)), _row(guardian_stats=json.dumps(changed)), True) == (
        "guardian_stats.qp_fallbacks",
        1,
        2,
    )
    # a key on one side only: the first in name order; NaN statistics equal
    more = {**stats, "a_new_count": 0, "zeta": 1}
    got = compare_rows(_row(guardian_stats=json.dumps(stats)), _row(guardian_stats=json.dumps(more)), True)
    assert got == ("guardian_stats.a_new_count", None, 0)
    got = compare_rows(_row(guardian_stats=json.dumps(more)), _row(guardian_stats=json.dumps(stats)), True)
    assert got == ("guardian_stats.a_new_count", 0, None)
    nan = {"ratio": math.nan}
    assert compare_rows(_row(guardian_stats=json.dumps(nan)), _row(guardian_stats=json.dumps(nan)), True) is None
    # none stored on either side, or an empty string: no statistics
    assert compare_rows(_row(guardian_stats=None), _row(guardian_stats=""), True) is None
    assert compare_rows(_row(guardian_stats=None), _row(guardian_stats='{"n": 1}'), True) == (
        "guardian_stats.n",
        None,
        1,
    )
    # in the stored row's order: the statistics before the columns after them
    got = compare_rows(
        _row(guardian_stats=json.dumps(stats)), _row(guardian_stats=json.dumps(changed), compute_time=9.0), True
    )
    assert got[0] == "guardian_stats.qp_fallbacks"


def test_an_error_by_its_first_line():
    a = _row(outcome="error", error="ValueError: boom\n  File x, line 1\n  more")
    b = _row(outcome="error", error="ValueError: boom\n  File y, line 2")
    assert compare_rows(a, b, True) is None
    c = _row(outcome="error", error="ValueError: bang\n  File x, line 1\n  more")
    assert compare_rows(a, c, True) == ("error", "ValueError: boom", "ValueError: bang")
    assert compare_rows(_row(error=None), _row(error=""), True) == ("error", None, "")
    assert compare_rows(_row(error="x"), _row(error=None), True) == ("error", "x", None)
    assert compare_rows(_row(error=""), _row(error="\nsecond"), True) is None  # its first line is empty too


def test_a_start_not_stored_leaves_the_columns_after_it_compared():
    assert compare_rows(_row(start=None), _row(start="abcd", compute_time=9.0), True) == ("compute_time", 0.12, 9.0)
