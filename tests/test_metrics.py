"""Table I aggregation (rmm_bench.metrics): every statistic on a small hand-made run."""

import math

import numpy as np
import pandas as pd
import pytest

from rmm_bench.metrics import aggregate, batch_rate, table_i, weighted_mean_std

NAN = float("nan")


def E(i, outcome, steps, compute, sim, active, speed, decision, pre, **extra):
    return {
        "episode": i,
        "outcome": outcome,
        "steps": steps,
        "compute_time": compute,
        "sim_time": sim,
        "active_sim_time": active,
        "final_speed": speed,
        "decision_mean": decision,
        "precompute_time": pre,
        **extra,
    }


# stored out of order; one errored episode; one that never stepped and had no sim time
RUN = [
    E(2, "collision", 5, 0.02, 4.0, 4.0, 1.4, 0.003, None, qp_fallbacks=3),
    E(0, "goal", 10, 0.02, 2.0, 0.5, 1.0, 0.001, 1.5, qp_fallbacks=2, nan_states=1),
    {"episode": 3, "outcome": "error", "qp_fallbacks": 5, "nan_states": 2},
    E(4, "collision", 4, 0.004, 1.0, 0.0, 0.6, NAN, 0.5),
    E(1, "goal", 0, 0.0, 0.0, 0.0, 2.0, 0.002, 0.0),
]


def test_every_statistic_by_hand():
    a = aggregate(RUN, batch_size=2)
    assert (a["episodes"], a["errors"], a["error_rate"]) == (5, 1, 0.2)
    # in episode order 0 1 | 2 3 | 4, the guardian error (3) a failure: goals 1 1 | 0 0 | 0, rates 1 0 0
    # weighted 2 2 1: mean 2/5, std sqrt((2 * 0.6^2 + 2 * 0.4^2 + 0.4^2) / 5); collisions 0 0 | 1 0 | 1
    # (stored order would give 0 1 | 0 1 for the goals)
    assert a["goal"] == pytest.approx((40.0, 100 * math.sqrt(0.24)))
    assert a["collision"] == pytest.approx((40.0, 100 * math.sqrt((2 * 0.4**2 + 2 * 0.1**2 + 0.6**2) / 5)))
    assert a["timeout"] == (0.0, 0.0)
    assert (a["total_goal"], a["total_collision"], a["total_timeout"]) == pytest.approx((40.0, 40.0, 0.0))
    # ms per step of the episodes that stepped: 2, 4, 1
    assert a["compute_ms"] == pytest.approx((7 / 3, math.sqrt(14 / 9)))
    # decision means 1, 3, 2 ms (the NaN one left out)
    assert a["decision_ms"] == pytest.approx((2.0, math.sqrt(2 / 3)))
    # active share of the episodes with sim time: 0.25, 1, 0
    assert a["intervention"] == pytest.approx((100 * 1.25 / 3, 100 * np.std([0.25, 1.0, 0.0])))
    assert a["steps"] == pytest.approx((4.75, np.std([10, 0, 5, 4])))
    assert a["precompute_s"] == pytest.approx((0.5, np.std([1.5, 0.0, 0.0, 0.5])))  # missing -> 0
    assert (a["qp_fallbacks"], a["nan_states"]) == (10, 3)  # counted over every episode, errored too
    assert a["collision_speed"] == pytest.approx((1.0, 0.4))


def test_empty_inputs_give_nan_not_zero():
    a = aggregate([])
    assert a.keys() == aggregate(RUN).keys()  # the same statistics as any run
    assert (a["episodes"], a["errors"], a["qp_fallbacks"], a["nan_states"]) == (0, 0, 0, 0)
    assert a["rate_spread"] == "batches"
    rest = [v for k, v in a.items() if k not in ("episodes", "errors", "qp_fallbacks", "nan_states", "rate_spread")]
    assert all(math.isnan(x) for v in rest for x in (v if isinstance(v, tuple) else (v,)))
    assert all(map(math.isnan, weighted_mean_std([], [])))
    assert all(map(math.isnan, weighted_mean_std([1.0, 2.0], [0, 0])))
    assert all(map(math.isnan, batch_rate([])))
    only_errors = aggregate([{"episode": 0, "outcome": "error"}])  # a guardian error: a failure, not a missing result
    assert only_errors["errors"] == 1 and only_errors["error_rate"] == 1.0
    assert only_errors["total_goal"] == 0.0 and only_errors["goal"][0] == 0.0
    assert only_errors["goal"][1] == pytest.approx(
        100 * 1.959963984540054**2 / 2 / (1 + 1.959963984540054**2)
    )  # Wilson, n = 1
    no_result = aggregate([{"episode": 0, "outcome": "error", "error_kind": "timeout"}])
    assert math.isnan(no_result["total_goal"]) and all(map(math.isnan, no_result["goal"]))


def test_batch_rate_batches_in_order_and_weights_by_size():
    # batches of 3: [1 1 0] [0 0]: rates 2/3 (3 episodes) and 0 (2)
    m, s = batch_rate([1, 1, 0, 0, 0], batch_size=3)
    assert m == pytest.approx(0.4)
    assert s == pytest.approx(math.sqrt((3 * (2 / 3 - 0.4) ** 2 + 2 * 0.4**2) / 5))
    assert weighted_mean_std([2.0, 4.0], [1, 3]) == pytest.approx((3.5, math.sqrt(0.75)))


def test_table_i_rows_per_agent_in_order_of_appearance():
    df = pd.DataFrame.from_records([dict(r, agent="z") for r in RUN] + [dict(RUN[1], agent="a")])
    t = table_i(df, batch_size=2)
    assert list(t.index) == ["z", "a"] and t.index.name == "agent"
    z = t.loc["z"]
    assert (z["goal"], z["goal_std"]) == pytest.approx((40.0, 100 * math.sqrt(0.24)))
    assert (z["errors"], z["qp_fallbacks"]) == (1, 10)
    assert z["compute_ms"] == pytest.approx(7 / 3) and z["compute_ms_std"] == pytest.approx(math.sqrt(14 / 9))
    assert (t.loc["a", "goal"], t.loc["a", "episodes"], t.loc["a", "intervention"]) == (100.0, 1, 25.0)


def test_table_i_batches_64_episodes_by_default():
    # 64 goals then one collision: batches of 64 and 1 (one batch of 65 would have no spread)
    df = pd.DataFrame.from_records(
        [dict(RUN[1], episode=i, agent="x", outcome="goal" if i < 64 else "collision") for i in range(65)]
    )
    m = 64 / 65
    row = table_i(df).loc["x"]
    assert row["goal"] == pytest.approx(100 * m)
    assert row["goal_std"] == pytest.approx(100 * math.sqrt((64 * (1 - m) ** 2 + m**2) / 65))
    assert aggregate(df.to_dict("records"))["goal"] == pytest.approx((row["goal"], row["goal_std"]))


def test_degenerate_inputs_give_nan_without_a_numpy_warning():
    """All weights zero, or every episode errored: NaN by the explicit branches, never by a 0/0 or
    the mean of an empty slice (which would print a RuntimeWarning in every report)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert all(map(math.isnan, weighted_mean_std([1.0, 2.0], [0, 0])))
        a = aggregate(
            [
                {"episode": 0, "outcome": "error", "error_kind": "timeout"},
                {"episode": 1, "outcome": "error", "error_kind": "lost_worker"},
            ]
        )
        t = table_i(
            pd.DataFrame.from_records([{"agent": "e", "episode": 0, "outcome": "error", "error_kind": "timeout"}])
        )
    assert [math.isnan(a[f"total_{k}"]) for k in ("goal", "collision", "timeout")] == [True] * 3
    assert (a["episodes"], a["errors"], a["error_rate"]) == (2, 2, 1.0)
    assert math.isnan(t.loc["e", "total_goal"]) and t.loc["e", "errors"] == 1


def test_episodes_with_equal_numbers_keep_their_stored_order():
    """A frame of two runs numbered alike (16 goals numbered 0-15, then 8 collisions numbered 0-7):
    sorted by episode with a stable sort, the order is g c g c ... (8 pairs) then 8 g; batches of 3
    have goal rates 2/3 1/3 2/3 1/3 2/3 2/3 1 1, so mean 2/3 and population std sqrt(1/18).
    An unstable sort may swap the pairs and change the spread."""
    rows = [dict(RUN[1], episode=i, outcome="goal") for i in range(16)] + [
        dict(RUN[1], episode=i, outcome="collision") for i in range(8)
    ]
    a = aggregate(rows, batch_size=3)
    assert a["goal"] == pytest.approx((100 * 2 / 3, 100 * math.sqrt(1 / 18)), rel=1e-12)
    assert a["collision"] == pytest.approx((100 / 3, 100 * math.sqrt(1 / 18)), rel=1e-12)
    row = table_i(pd.DataFrame.from_records([dict(r, agent="x") for r in rows]), batch_size=3).loc["x"]
    assert (row["goal"], row["goal_std"]) == pytest.approx(a["goal"], rel=1e-12)


def test_fewer_than_two_batches_give_the_wilson_interval_not_zero():
    """One batch (64 episodes, batch size 64): the std over batches would be 0; the spread is
    then the 95% Wilson half-width, by hand for 35 of 64 (p = 0.546875, z = 1.959964):
    z sqrt(p (1-p) / 64 + z^2 / 16384) / (1 + z^2 / 64) = 0.125597 / 1.060023 = 0.118485"""
    from rmm_bench.metrics import rate_spread, wilson_half_width

    flags = [1] * 35 + [0] * 29
    m, s = batch_rate(flags, 64)
    z = 1.959963984540054
    p = 35 / 64
    assert m == p and s == pytest.approx(z * math.sqrt(p * (1 - p) / 64 + z * z / 16384) / (1 + z * z / 64), rel=1e-12)
    assert s == pytest.approx(0.118485, abs=1e-6)
    assert wilson_half_width(0.0, 10) > 0  # not 0 at a rate of 0, unlike p (1 - p)
    assert math.isnan(wilson_half_width(0.5, 0))
    assert rate_spread(64, 64) == "wilson95" and rate_spread(65, 64) == "batches"
    m2, s2 = batch_rate(flags + [1], 64)  # two batches (64 and 1): the batch std again
    assert s2 == pytest.approx(weighted_mean_std([35 / 64, 1.0], [64, 1])[1])
    agg = aggregate(
        [
            {
                "episode": i,
                "outcome": "goal" if f else "collision",
                "steps": 10,
                "compute_time": 0.01,
                "sim_time": 1.0,
                "active_sim_time": 0.0,
            }
            for i, f in enumerate(flags)
        ],
        batch_size=64,
    )
    assert agg["rate_spread"] == "wilson95" and agg["goal"] == pytest.approx((100 * p, 100 * s))
    centre = (p + z * z / 128) / (1 + z * z / 64)  # the interval is centred here, not on p
    assert agg["goal_ci"] == pytest.approx((100 * (centre - s), 100 * (centre + s)))
    from rmm_bench.metrics import wilson_interval

    assert wilson_interval(1.0, 2)[1] == 1.0 and 0.0 < wilson_interval(1.0, 2)[0] < 0.5  # within [0, 1]


def test_the_table_says_which_spread_and_shows_measured_decision_time_under_a_fixed_clock():
    from rmm_bench.report import format_tables

    eps = [
        {
            "episode": i,
            "outcome": "goal" if i % 3 else "collision",
            "steps": 10,
            "compute_time": 0.01,
            "decision_mean": 0.0004 * (1 + i % 2),
            "sim_time": 1.0,
            "active_sim_time": 0.0,
        }
        for i in range(20)
    ]
    row = {"agent": "a", "obs": "none", "n_obst": 5, **aggregate(eps, batch_size=16)}
    md = format_tables([row], batch_size=16, measured=True)["md"]
    header, _, line, _, note = md.splitlines()
    assert "| Policy compute time [ms] | Measured decision time [ms] |" in header
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[4] == "1.00 ± 0.00" and cells[5] == "0.60 ± 0.20"  # 0.4 and 0.8 ms, alternately
    assert note == "Rates: mean ± std over batches of 16 episodes (the paper's)."  # 20 > 16: two batches
    row1 = {"agent": "a", "obs": "none", "n_obst": 5, **aggregate(eps[:16], batch_size=16)}
    md1 = format_tables([row1], batch_size=16)["md"]
    assert "Measured" not in md1.splitlines()[0]
    cells1 = [c.strip() for c in md1.splitlines()[2].strip("|").split("|")]
    lo, hi = row1["goal_ci"]
    assert cells1[5] == f"{row1['goal'][0]:.1f} [{lo:.1f}, {hi:.1f}]†" and cells1[5].startswith("62.5 [")
    assert md1.splitlines()[2].count("†") == 3  # success, collision and timeout
    assert md1.splitlines()[-1].endswith(
        "†: fewer than two batches, so the rate is followed by its 95% Wilson "
        "score interval over the episodes, [low, high]."
    )


def test_table_i_names_the_wilson_interval_ends():
    import pandas as pd

    eps = [
        {
            "agent": "a",
            "episode": i,
            "outcome": "goal" if i % 2 else "collision",
            "steps": 10,
            "compute_time": 0.01,
            "sim_time": 1.0,
            "active_sim_time": 0.0,
        }
        for i in range(8)
    ]
    t = table_i(pd.DataFrame.from_records(eps), batch_size=64)
    row = t.loc["a"]
    assert row["rate_spread"] == "wilson95" and "goal_ci_std" not in t.columns
    assert (row["goal_ci_low"], row["goal_ci_high"]) == pytest.approx(aggregate(eps, 64)["goal_ci"])
    assert row["goal_ci_low"] < 50.0 < row["goal_ci_high"]
