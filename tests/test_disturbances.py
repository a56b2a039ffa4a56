"""Disturbances (rmm_envs.disturbances): the string form read back, every bad input named, draws a
function of the episode seed and the sim-time step only, and each kind changing what it should and
nothing else."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rmm_envs.autonomy import ObservationLayout
from rmm_envs.disturbances import (
    KINDS,
    Disturbance,
    DisturbanceError,
    Realisation,
    SystemSupport,
    parse_disturbances,
)

LAYOUT = ObservationLayout.of(
    ("time", 1), ("goal", 2), ("heading", 1), ("speed", 1), ("rays", 12), ray_angles=2 * np.pi * np.arange(12) / 12
)
HIGH = np.array([np.inf, np.inf, np.inf, np.pi, 2.0] + [10.0] * 12)
SUPPORT = SystemSupport(
    dt=0.1,
    horizon=100.0,
    layout=LAYOUT,
    obs_high=HIGH,
    action_low=np.array([-0.25, -0.5]),
    action_high=np.array([0.25, 0.5]),
    rates={"x": 0, "y": 1},
    parameters={"turn_gain": 1.0, "accel_gain": 1.0, "v_max": 2.0},
    system="Dubins4D",
)
OBS = np.concatenate([[3.0, 1.0, -1.0, 0.5, 1.5], np.full(12, 5.0)]).astype(np.float32)


def realise(text: str, seed: int = 7, support: SystemSupport = SUPPORT) -> Realisation:
    return Realisation(parse_disturbances(text), support, seed)


# ---------------------------------------------------------------- the string form


def test_the_string_form_reads_kind_components_level_and_shape():
    (d,) = parse_disturbances("obs-noise.speed+rays=0.05@step")
    assert (d.kind, d.on, d.level, d.shape) == ("obs-noise", ("rays", "speed"), 0.05, "step")
    assert str(d) == "obs-noise.rays+speed=0.05@step"
    (d,) = parse_disturbances("act-delay=2")
    assert (d.level, d.shape, str(d)) == (2.0, "none", "act-delay=2")
    assert parse_disturbances(None) == () == parse_disturbances("") == parse_disturbances([])
    assert [str(x) for x in parse_disturbances("dyn-rate=0.2; ray-dropout=0.1")] == ["dyn-rate=0.2", "ray-dropout=0.1"]


@given(
    kind=st.sampled_from(["obs-noise", "act-noise", "dyn-rate"]),
    level=st.floats(0, 100, allow_nan=False),
    shape=st.sampled_from(["", "white", "uniform", "step", "periodic"]),
)
def test_a_disturbance_reads_back_from_its_string(kind, level, shape):
    if kind == "dyn-rate" and shape == "impulse":
        return
    d = Disturbance(kind, level, shape)
    assert Disturbance.parse(str(d)) == d


@pytest.mark.parametrize(
    ("text", "names"),
    [
        ("wind-shear=1", ["'wind-shear'", "obs-noise"]),
        ("obs-noise=-0.1", ["-0.1", "negative", "standard deviation"]),
        ("ray-dropout=1.5", ["1.5", "[0, 1]"]),
        ("act-gain=-0.1", ["-0.1", "[0, 1]"]),
        ("mismatch=1", ["1.0", "[0, 1)"]),
        ("obs-noise=nan", ["nan", "not finite"]),
        ("dyn-rate=inf", ["inf", "not finite"]),
        ("act-delay=1.5", ["1.5", "whole number"]),
        ("act-delay=-1", ["-1", "whole number"]),
        ("obs-noise=0.1@sawtooth", ["'sawtooth'", "white"]),
        ("act-gain=0.1@white", ["'white'", "uniform"]),
        ("obs-noise=loud", ["'loud'", "not a number"]),
        ("obs-noise", ["'obs-noise'", "KIND[.COMPONENTS]=LEVEL"]),
        ("=0.1", ["'=0.1'", "KIND"]),
        ("act-noise.steer=0.1", ["'steer'", "whole control"]),
        ("obs-noise.rays+rays=0.1", ["distinct"]),
        ("obs-noise=0.1;obs-noise=0.2", ["twice"]),
    ],
)
def test_bad_input_is_one_line_naming_the_value(text, names):
    with pytest.raises(DisturbanceError) as e:
        parse_disturbances(text)
    msg = str(e.value)
    assert "\n" not in msg
    for n in names:
        assert n in msg


@pytest.mark.parametrize("spec", [3, {"obs-noise": 0.1}, [0.1]])
def test_a_spec_of_the_wrong_type_is_named(spec):
    with pytest.raises(DisturbanceError, match="string"):
        parse_disturbances(spec)


@pytest.mark.parametrize(
    ("text", "support", "names"),
    [
        ("obs-noise.lidar=0.1", SUPPORT, ["'lidar'", "rays"]),
        ("ray-dropout.speed=0.1", SUPPORT, ["rays only"]),
        ("dyn-rate.z=0.1", SUPPORT, ["'z'", "x, y"]),
        ("mismatch.mass=0.1", SUPPORT, ["'mass'", "turn_gain"]),
        ("dyn-rate=0.1", SystemSupport(dt=0.1, horizon=10.0), ["no rate disturbance"]),
        ("impulse=0.1", SystemSupport(dt=0.1, horizon=10.0, system="CartWall"), ["CartWall", "no rate"]),
        ("act-noise=0.1", SystemSupport(dt=0.1, horizon=10.0), ["no continuous control"]),
        ("mismatch=0.1", SystemSupport(dt=0.1, horizon=10.0), ["no parameters"]),
        ("obs-noise=0.1", SystemSupport(dt=0.1, horizon=10.0), ["no observation layout"]),
    ],
)
def test_a_disturbance_a_system_does_not_take_is_refused(text, support, names):
    with pytest.raises(DisturbanceError) as e:
        realise(text, support=support)
    for n in names:
        assert n in str(e.value)


# ---------------------------------------------------------------- draws


def test_the_same_seed_gives_the_same_draws_and_another_seed_others():
    text = "obs-noise=0.1;act-noise=0.1;dyn-rate=0.2@white;mismatch=0.2"
    a, b, c = realise(text, 1), realise(text, 1), realise(text, 2)
    for t in (0.0, 0.3, 57.1):
        assert np.array_equal(a.observation(OBS, t), b.observation(OBS, t))
        assert np.array_equal(a.rate(t, 4), b.rate(t, 4))
        assert not np.array_equal(a.observation(OBS, t), c.observation(OBS, t))
    assert a.parameters == b.parameters != c.parameters


def test_a_value_depends_on_the_sim_time_step_not_on_the_order_of_queries():
    """One agent acts every step, another only now and then: they meet the same values."""
    text = "obs-noise=0.1@white;dyn-rate=0.3@white;ray-dropout=0.2"
    every, some = realise(text), realise(text)
    seen = {k: (every.observation(OBS, k * 0.1), every.rate(k * 0.1, 4)) for k in range(0, 1200)}
    for k in (1100, 3, 600, 257, 255, 256, 3):
        o, r = some.observation(OBS, k * 0.1), some.rate(k * 0.1, 4)
        assert np.array_equal(o, seen[k][0]) and np.array_equal(r, seen[k][1])
    assert every.step_of(0.30000000000000004) == 3 == every.step_of(0.3) == every.step_of(0.39)


def test_adding_another_kind_leaves_a_kind_s_draws_as_they_were():
    alone, together = realise("obs-noise.rays=0.1"), realise("act-noise=0.2;obs-noise.rays=0.1;dyn-rate=0.1")
    for t in (0.0, 1.0, 12.3):
        assert np.array_equal(alone.observation(OBS, t), together.observation(OBS, t))


# ---------------------------------------------------------------- each kind, and nothing else


def test_observation_noise_touches_its_fields_only_with_its_standard_deviation():
    r = realise("obs-noise.rays=0.5")
    rays = np.array([r.observation(OBS, k * 0.1)[5:] for k in range(4000)])
    first = r.observation(OBS, 0.0)
    assert np.array_equal(first[:5], OBS[:5])  # time, goal, heading, speed untouched
    assert first.dtype == OBS.dtype
    assert abs(rays.std() - 0.5) < 0.02 and abs(rays.mean() - 5.0) < 0.02
    default = realise("obs-noise=0.1").observation(OBS, 0.0)
    assert default[0] == OBS[0] and np.all(default[1:] != OBS[1:])  # all but time


def test_rays_stay_within_their_range_under_noise_and_bias():
    near = OBS.copy()
    near[5:] = [0.05] * 6 + [9.95] * 6
    out = np.array([realise("obs-noise.rays=1.0").observation(near, k * 0.1)[5:] for k in range(200)])
    assert out.min() == 0.0 and out.max() == 10.0
    assert np.array_equal(realise("obs-bias=-0.5").observation(OBS, 0.0)[5:], np.full(12, 4.5, np.float32))
    assert np.array_equal(realise("obs-bias.speed=0.25").observation(OBS, 0.0)[4], np.float32(1.75))


def test_a_dropout_reads_the_maximum_with_its_probability():
    r = realise("ray-dropout=0.3")
    rays = np.array([r.observation(OBS, k * 0.1)[5:] for k in range(3000)])
    assert set(np.unique(rays)) == {5.0, 10.0}
    assert abs((rays == 10.0).mean() - 0.3) < 0.01
    assert np.array_equal(realise("ray-dropout=0").observation(OBS, 1.0), OBS)
    assert np.all(realise("ray-dropout=1").observation(OBS, 1.0)[5:] == 10.0)


def test_action_noise_is_a_fraction_of_each_half_range_and_clipped():
    r = realise("act-noise=0.1")
    u = np.array([r.control(np.zeros(2), k * 0.1) for k in range(4000)])
    assert np.allclose(u.std(axis=0), [0.025, 0.05], rtol=0.05)
    hard = realise("act-noise=5")
    u = np.array([hard.control(np.array([0.2, 0.4]), k * 0.1) for k in range(100)])
    assert u[:, 0].min() == -0.25 and u[:, 0].max() == 0.25 and u[:, 1].max() == 0.5


def test_a_gain_error_is_held_for_the_episode_within_its_range():
    r = realise("act-gain=0.2")
    assert np.all(np.abs(r.gain - 1.0) <= 0.2) and np.all(r.gain != 1.0)
    u = np.array([0.1, 0.2])
    assert np.array_equal(r.control(u, 0.0), u * r.gain) and np.array_equal(r.control(u, 50.0), u * r.gain)


def test_a_delay_applies_the_control_commanded_k_steps_before():
    r = realise("act-delay=2")
    commanded = [np.array([0.01 * i, -0.01 * i]) for i in range(6)]
    applied = [r.control(u, i * 0.1) for i, u in enumerate(commanded)]
    expected = [commanded[0], commanded[0], commanded[0], commanded[1], commanded[2], commanded[3]]
    for a, e in zip(applied, expected, strict=True):
        assert np.array_equal(a, e)
    r0 = realise("act-delay=0")
    assert np.array_equal(r0.control(commanded[4], 0.0), commanded[4])


def test_a_rate_disturbance_is_bounded_held_and_on_its_components():
    r = realise("dyn-rate=0.3")
    d = r.rate(0.0, 4)
    assert np.all(np.abs(d[:2]) <= 0.3) and np.all(d[:2] != 0) and np.all(d[2:] == 0)
    assert np.array_equal(r.rate(80.0, 4), d)  # uniform: one draw per episode
    w = np.array([realise("dyn-rate.y=0.3@white").rate(k * 0.1, 4) for k in range(1000)])
    assert np.all(w[:, [0, 2, 3]] == 0) and np.abs(w[:, 1]).max() <= 0.3 and len(np.unique(w[:, 1])) == 1000


def test_a_step_starts_at_its_onset_in_the_first_half_and_holds():
    r = realise("dyn-rate=0.3@step")
    vals = np.array([r.rate(k * 0.1, 2) for k in range(1000)])
    on = np.flatnonzero(np.any(vals != 0, axis=1))
    assert 0 < on[0] < 500 and np.array_equal(on, np.arange(on[0], 1000))
    assert np.all(vals[on] == vals[on[0]])


def test_a_periodic_shape_is_a_sine_of_period_between_2_and_10_s():
    r = realise("dyn-rate.x=0.3@periodic")
    x = np.array([r.rate(k * 0.1, 2)[0] for k in range(2000)])
    assert np.abs(x).max() <= 0.3 and x.max() > 0 > x.min()
    crossings = np.flatnonzero(np.diff(np.sign(x)) != 0)
    period = 2 * np.mean(np.diff(crossings)) * 0.1
    assert 2.0 <= period <= 10.0


def test_an_impulse_is_one_push_of_its_size_at_one_step():
    r = realise("impulse=0.5")
    vals = np.array([r.rate(k * 0.1, 4) for k in range(1000)])
    hit = np.flatnonzero(np.any(vals != 0, axis=1))
    assert len(hit) == 1 and hit[0] < 500
    assert math.isclose(np.linalg.norm(vals[hit[0]]) * 0.1, 0.5)


def test_a_mismatch_scales_each_parameter_within_its_range_or_only_those_named():
    r = realise("mismatch=0.2")
    for name, nominal in SUPPORT.parameters.items():
        assert abs(r.parameters[name] / nominal - 1.0) <= 0.2 and r.parameters[name] != nominal
    some = realise("mismatch.v_max=0.2")
    assert some.parameters["turn_gain"] == 1.0 == some.parameters["accel_gain"]
    assert some.parameters["v_max"] == r.parameters["v_max"]  # the same draw for that parameter


def test_no_disturbance_changes_nothing():
    r = Realisation((), SUPPORT, 3)
    assert not r.active
    assert np.array_equal(r.observation(OBS, 1.0), OBS)
    assert np.array_equal(r.control(np.array([0.1, -0.2]), 1.0), [0.1, -0.2])
    assert np.array_equal(r.rate(1.0, 4), np.zeros(4)) and r.parameters == dict(SUPPORT.parameters)


def test_every_kind_is_documented_in_the_package_docstring():
    import rmm_envs.disturbances as pkg

    for kind in KINDS:
        assert f"``{kind}``" in (pkg.__doc__ or "")


def test_a_delay_is_counted_in_sim_time_not_in_calls():
    """An agent that calls twice within a step (the non-blocking env's intervals) meets the same
    delayed control as one that calls once per step."""
    once, twice = realise("act-delay=2"), realise("act-delay=2")
    u = [np.array([0.01 * k, 0.0]) for k in range(8)]
    a = [once.control(u[k], 0.1 * k) for k in range(8)]
    b = []
    for k in range(8):
        b.append(twice.control(u[k], 0.1 * k))
        twice.control(u[k], 0.1 * k + 0.05)  # a second call within the step, commanding the same
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x, y)
    assert np.array_equal(a[5], u[3]) and np.array_equal(a[1], u[0])
