"""Wrong statistics that an earlier suite let through (issue 49): each test here fails on one
single-line bug that was seeded into a copy and passed every other test.

- ``paired_bootstrap``: its interval at level L leaves (1 - L) / 2 in each tail (``tail = 1 - L``
  made every 95% interval a 90% one); checked against the exact bootstrap distribution;
- Newcombe's intervals at 90%, 95% and 99% by hand;
- compare's floor: "where every one collided" counts the episodes every agent collided in (``any``
  counted those where one did);
- calibration (rmm_bench.calibration): the constant predictor's Brier score is the labels' variance, so the skill score is
  ``1 - Brier / variance`` (it was computed from the predictions).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom, norm

from rmm_bench.compare import _floor_line
from rmm_bench.paired import Z95, newcombe_paired, newcombe_unpaired, paired_bootstrap

LEVELS = [0.5, 0.8, 0.9, 0.95, 0.99]

# ---------------------------------------------------------------- the paired bootstrap


@pytest.mark.parametrize("level", LEVELS)
def test_bootstrap_interval_at_each_level_is_the_exact_bootstraps(level):
    """``x - y`` is 1 in 120 of 400 episodes and 0 in the rest: a resample's mean is then exactly
    Binomial(400, 0.3) / 400, so the percentile interval at level L is that distribution's
    (1 - L) / 2 and (1 + L) / 2 quantiles (20,000 resamples: within one count of them)."""
    n, k = 400, 120
    x, y = np.r_[np.ones(k), np.zeros(n - k)], np.zeros(n)
    d, lo, hi = paired_bootstrap(x, y, seed=1, resamples=20_000, level=level)
    tail = (1.0 - level) / 2
    assert d == 0.3
    assert lo * n == pytest.approx(binom.ppf(tail, n, k / n), abs=1.0 + 1e-9)
    assert hi * n == pytest.approx(binom.ppf(1.0 - tail, n, k / n), abs=1.0 + 1e-9)


def test_bootstrap_interval_widens_with_the_level_and_defaults_to_95():
    rng = np.random.default_rng(5)
    x, y = rng.normal(0.4, 1.0, 200), rng.normal(0.0, 1.0, 200)
    widths = []
    for level in LEVELS:
        d, lo, hi = paired_bootstrap(x, y, seed=3, resamples=4000, level=level)
        assert lo < d < hi
        widths.append(hi - lo)
    assert widths == sorted(widths) and len(set(widths)) == len(widths)
    assert paired_bootstrap(x, y, seed=3, resamples=4000) == paired_bootstrap(x, y, 3, 4000, 0.95)
    # normal data: the 95% percentile interval is close to mean +- 1.96 standard errors
    d, lo, hi = paired_bootstrap(x, y, seed=3, resamples=4000)
    se = np.std(x - y) / math.sqrt(200)
    assert lo == pytest.approx(d - Z95 * se, abs=0.25 * se) and hi == pytest.approx(d + Z95 * se, abs=0.25 * se)


def test_bootstrap_resamples_whole_pairs():
    """A resample draws episodes, not x and y separately: with x = y + 1 the difference is 1 in every
    resample, whatever y is."""
    y = np.random.default_rng(0).normal(0, 5, 50)
    d, lo, hi = paired_bootstrap(y + 1.0, y, seed=0, resamples=300)
    assert d == pytest.approx(1.0) and lo == pytest.approx(1.0) and hi == pytest.approx(1.0)


def test_bootstrap_defaults_are_seed_0_2000_resamples_95_percent():
    rng = np.random.default_rng(11)
    x, y = rng.normal(0.2, 1.0, 60), rng.normal(0.0, 1.0, 60)
    assert paired_bootstrap(x, y) == paired_bootstrap(x, y, seed=0, resamples=2000, level=0.95)
    assert paired_bootstrap(x, y) != paired_bootstrap(x, y, seed=1)
    assert paired_bootstrap(x, y) != paired_bootstrap(x, y, resamples=2001)


def test_every_resample_is_drawn_and_any_episode_can_be():
    """One resample: its mean is the interval (no slot left unfilled); episode 0 alone differs:
    2 episodes, a resample of both copies of episode 0 (1 in 4) reaches 1."""
    assert paired_bootstrap(np.full(5, 3.0), np.full(5, 1.0), resamples=1) == (2.0, 2.0, 2.0)
    assert paired_bootstrap(np.full(5, 3.0), np.full(5, 1.0), resamples=2) == (2.0, 2.0, 2.0)
    d, lo, hi = paired_bootstrap(np.array([1.0, 0.0]), np.zeros(2), seed=4, resamples=1)
    assert d == 0.5 and lo == hi and lo in (0.0, 0.5, 1.0)
    assert paired_bootstrap(np.array([1.0, 0.0]), np.zeros(2), resamples=400) == (0.5, 0.0, 1.0)


def test_more_resamples_than_one_batch_of_draws():
    """3,000 episodes and 2,000 resamples are drawn in batches of 1,333 (4 million indices at a
    time): every resample filled, the interval the normal approximation's to within 10%."""
    rng = np.random.default_rng(2)
    x, y = rng.normal(0.5, 1.0, 3000), rng.normal(0.0, 1.0, 3000)
    d, lo, hi = paired_bootstrap(x, y, seed=5, resamples=2000)
    se = np.std(x - y) / math.sqrt(3000)
    assert d - lo == pytest.approx(Z95 * se, rel=0.1) and hi - d == pytest.approx(Z95 * se, rel=0.1)


# ---------------------------------------------------------------- Newcombe by hand at several levels


def _wilson(x: int, n: int, z: float) -> tuple[float, float, float]:
    """Wilson's score interval written out: centre (2x + z^2) / (2(n + z^2)), half-width
    z sqrt(x(n - x)/n + z^2/4) / (n + z^2)."""
    centre = (2 * x + z * z) / (2 * (n + z * z))
    half = z * math.sqrt(x * (n - x) / n + z * z / 4) / (n + z * z)
    return x / n, max(0.0, centre - half), min(1.0, centre + half)


@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_newcombe_paired_by_hand_at_each_level(level):
    # 60 paired episodes: both 6, A alone 14, B alone 4, neither 36
    z = float(norm.ppf(0.5 + level / 2))
    pa, la, ua = _wilson(20, 60, z)
    pb, lb, ub = _wilson(10, 60, z)
    # both * neither - a_only * b_only = 216 - 56 = 160 > n / 2 = 30: phi = (160 - 30) / sqrt(20 * 40 * 10 * 50)
    phi = 130 / math.sqrt(20 * 40 * 10 * 50)
    d = 1 / 6
    low = d - math.sqrt((pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2)
    high = d + math.sqrt((ua - pa) ** 2 - 2 * phi * (ua - pa) * (pb - lb) + (pb - lb) ** 2)
    got = newcombe_paired(6, 14, 4, 36, z)
    assert got == pytest.approx((d, low, high), abs=1e-12)
    if level == 0.95:
        assert newcombe_paired(6, 14, 4, 36) == got  # the default is 95%


@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_newcombe_paired_with_a_negative_correlation_by_hand(level):
    # both 2, A alone 9, B alone 7, neither 2 (n = 20): 4 - 63 < 0, phi kept negative
    z = float(norm.ppf(0.5 + level / 2))
    pa, la, ua = _wilson(11, 20, z)
    pb, lb, ub = _wilson(9, 20, z)
    phi = -59 / math.sqrt(11 * 9 * 9 * 11)
    low = 0.1 - math.sqrt((pa - la) ** 2 - 2 * phi * (pa - la) * (ub - pb) + (ub - pb) ** 2)
    high = 0.1 + math.sqrt((ua - pa) ** 2 - 2 * phi * (ua - pa) * (pb - lb) + (pb - lb) ** 2)
    assert newcombe_paired(2, 9, 7, 2, z) == pytest.approx((0.1, low, high), abs=1e-12)


def test_newcombe_paired_at_the_edges():
    # no episode: no estimate
    assert all(math.isnan(v) for v in newcombe_paired(0, 0, 0, 0))
    # every episode failed under both: phi has a zero margin and is 0; the interval is the
    # difference of two identical Wilson intervals at p = 1
    p, lw, up = _wilson(10, 10, Z95)
    assert p == up == 1.0
    assert newcombe_paired(10, 0, 0, 0) == pytest.approx((0.0, -(p - lw), p - lw), abs=1e-12)
    # clipped to [-1, 1]: A always, B never, a handful of episodes
    d, lo, hi = newcombe_paired(0, 3, 0, 0)
    assert d == 1.0 and hi == 1.0 and 0 < lo < 1
    pa, la, _ = _wilson(3, 3, Z95)
    _, _, ub = _wilson(0, 3, Z95)
    assert lo == pytest.approx(1.0 - math.hypot(pa - la, ub), abs=1e-12)
    d, lo, hi = newcombe_paired(0, 0, 3, 0)
    assert d == -1.0 and lo == -1.0 and -1 < hi < 0
    # the same failures under both (5 * 15 - 0 = 75 > 20 / 2): phi = (75 - 10) / (5 * 15)
    pa, la, ua = _wilson(5, 20, Z95)
    phi = 65 / math.sqrt(5 * 15 * 5 * 15)
    low = -math.sqrt((pa - la) ** 2 - 2 * phi * (pa - la) * (ua - pa) + (ua - pa) ** 2)
    high = math.sqrt((ua - pa) ** 2 - 2 * phi * (ua - pa) * (pa - la) + (pa - la) ** 2)
    assert newcombe_paired(5, 0, 0, 15) == pytest.approx((0.0, low, high), abs=1e-12)


@pytest.mark.parametrize("level", [0.9, 0.95, 0.99])
def test_newcombe_unpaired_by_hand_at_each_level(level):
    z = float(norm.ppf(0.5 + level / 2))
    pa, la, ua = _wilson(56, 70, z)
    pb, lb, ub = _wilson(48, 80, z)
    got = newcombe_unpaired(56, 70, 48, 80, z)
    assert got == pytest.approx((0.2, 0.2 - math.hypot(pa - la, ub - pb), 0.2 + math.hypot(ua - pa, pb - lb)))
    assert all(math.isnan(v) for v in newcombe_unpaired(1, 0, 1, 4)) and all(
        math.isnan(v) for v in newcombe_unpaired(1, 4, 0, 0)
    )
    # clipped: 5/5 against 0/5
    d, lo, hi = newcombe_unpaired(5, 5, 0, 5, z)
    assert d == 1.0 and hi == 1.0 and 0 < lo < 1


def test_intervals_never_leave_minus_one_to_one_even_by_a_rounding():
    """Unclipped, B always and A never over 25 paired episodes gives a lower bound of
    -1.0000000000000002 (and 0/1 against 27/27 unpaired): the bounds are clipped to [-1, 1]."""
    assert newcombe_paired(0, 0, 25, 0)[1] == -1.0 and newcombe_paired(0, 25, 0, 0)[2] == 1.0
    assert newcombe_unpaired(0, 1, 27, 27)[1] == -1.0 and newcombe_unpaired(27, 27, 0, 1)[2] == 1.0


# ---------------------------------------------------------------- compare's floor


def _floor(outcomes: dict[str, list[str]], doomed: list) -> pd.DataFrame:
    episodes = [3, 5, 8, 13, 21][: len(doomed)]
    return pd.DataFrame(
        {
            "group": "g",
            "episode": episodes,
            "seed": [100 + e for e in episodes],
            "doomed": doomed,
            **{f"outcome:{a}": o for a, o in outcomes.items()},
        }
    )


def test_the_floor_counts_episodes_where_every_agent_collided():
    outcomes = {
        "a": ["collision", "collision", "timeout", "collision", "collision"],
        "b": ["collision", "timeout", "collision", "collision", "error"],
        "c": ["collision", "collision", "collision", "timeout", "collision"],
    }
    # every one collided in episode 3 only (each other episode has a timeout or an error in it)
    floor = _floor(outcomes, [True, False, False, True, False])
    assert _floor_line(floor, ["a", "b", "c"]) == (
        "Floor: 5 episodes that every one of a, b, c failed (no goal), 1 where every one collided, "
        "2 of them from doomed starts; first: 3,5,8,13,21"
    )
    every = {a: ["collision"] * 4 for a in "ab"}
    assert ", 4 where every one collided, 0 of them" in _floor_line(_floor(every, [False] * 4), ["a", "b"])
    never = {"a": ["timeout"] * 2, "b": ["collision"] * 2}
    assert ", 0 where every one collided" in _floor_line(_floor(never, [False, False]), ["a", "b"])
    # a start not assessed: no doomed count
    line = _floor_line(_floor(every, [True, None, False, True]), ["a", "b"])
    assert ", 4 where every one collided; first: 3,5,8,13" in line and "doomed" not in line


def test_the_floor_line_lists_its_first_eight_episodes():
    floor = pd.DataFrame(
        {
            "group": "g",
            "episode": list(range(10, 20)),
            "seed": list(range(10)),
            "doomed": [False] * 10,
            "outcome:a": ["collision"] * 10,
            "outcome:b": ["timeout"] * 10,
        }
    )
    assert _floor_line(floor, ["a", "b"]).endswith(
        ", 0 where every one collided, 0 of them from doomed starts; first: 10,11,12,13,14,15,16,17"
    )


def test_an_empty_floor_says_so():
    empty = _floor({"a": [], "b": []}, [])
    assert _floor_line(empty, ["a", "b"]) == "Floor: no episode that every one of a, b failed."


# ---------------------------------------------------------------- calibration's skill score


class _Model:
    def __init__(self, pred):
        self.pred = np.asarray(pred, float)

    def predict(self, obs):
        return self.pred


class _Data:
    def __init__(self, risk):
        self.risk = np.asarray(risk, float)
        self.obs = np.zeros((self.risk.size, 2))
        self.config_id = np.arange(self.risk.size) // 2
        self.sha256 = "f" * 64


def test_brier_of_the_constant_and_the_skill_score_by_hand(tmp_path, monkeypatch):
    """Labels 0, 0.5, 1, 0.5 and predictions 0.1, 0.4, 0.9, 0.6: Brier 0.01; the labels' mean is
    0.5, so the best constant's Brier is (0.25 + 0 + 0.25 + 0) / 4 = 0.125 and the skill
    1 - 0.01 / 0.125 = 0.92 (from the predictions it would be 0.085 and 0.882)."""
    from rmm_bench import calibration
    from rmm_envs.risk import datagen, dataset
    from rmm_guardians.lrmm import model

    data = _Data([0.0, 0.5, 1.0, 0.5])
    monkeypatch.setattr(datagen, "main", lambda argv: 0)
    monkeypatch.setattr(dataset, "load_dataset", lambda path: data)
    monkeypatch.setattr(model.LRMMModel, "load", staticmethod(lambda path: _Model([0.1, 0.4, 0.9, 0.6])))
    r = calibration.calibrate("Dubins4D", 2026, 1, tmp_path)
    assert r["brier"] == pytest.approx(0.01)
    assert r["brier_constant"] == pytest.approx(0.125)
    assert r["skill"] == pytest.approx(0.92)
    assert r["mean_label"] == 0.5 and r["mean_pred"] == pytest.approx(0.5)
    assert r["labels"] == 4 and r["worlds"] == 2
    # labels all alike: no constant to beat, no skill
    monkeypatch.setattr(dataset, "load_dataset", lambda path: _Data([0.3] * 4))
    r = calibration.calibrate("Dubins4D", 2026, 1, tmp_path / "flat")
    assert r["brier_constant"] == 0.0 and math.isnan(r["skill"])
