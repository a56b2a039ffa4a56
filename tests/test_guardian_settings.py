"""The cbf and hj guardians' frozen settings objects: checked once (a bad value refused by name),
named presets equal to the -paper guardians' former arguments, and the constructors' keyword
arguments (and so ``--agent-opt``) building them."""

from __future__ import annotations

import dataclasses
import inspect
import math

import pytest

from rmm_guardians.cbf.guardian import CBFGuardian, CBFPaperGuardian
from rmm_guardians.cbf.settings import CBF_PRESETS, CBFSettings
from rmm_guardians.hj.guardian import HJGuardian, HJPaperGuardian
from rmm_guardians.hj.settings import HJ_PRESETS, HJSettings
from rmm_guardians.registry import accepts_argument, make_guardian

#: the constructors' keyword defaults before the settings objects (CBFGuardian, HJGuardian)
OLD_CBF = dict(
    p1=0.7535,
    p2=0.6664,
    inflation=1.05,
    gamma_vmin=1.0,
    gamma_vmax=1.0,
    lambda_theta=1.0,
    lambda_v=1.0,
    p_theta=1.0,
    p_v=1.0,
    u1_bounds=None,
    u2_bounds=None,
    v_bounds=None,
    active_atol=1e-3,
    active_rtol=0.0,
    low_speed_stop=False,
    max_obstacles=64,
    eps=1e-6,
    predict_latency=True,
    recovery=True,
    v_stuck=0.05,
    lap_guess=0.1,
    goal_aware_margin=True,
    solver="osqp",
    maze=None,
    reference="nominal",
    quadrotor=None,
)
OLD_HJ = dict(
    grid=None,
    grid_n=None,
    horizon=4.0,
    order=2,
    rk=3,
    cfl=0.8,
    rule="distance",
    margin=None,
    delay=1,
    lap=None,
    disturbance=0.0,
    cache_dir=None,
    cache=True,
    cache_max_files=64,
    mode="avoid",
    ra_horizon=10.0,
    ra_margin=0.5,
    backend="auto",
    standstill_lookup=True,
    threads=None,
    maze=None,
    quadrotor=None,
)
#: the -paper guardians' former keyword defaults (CBFPaperGuardian.__init__, HJPaperGuardian.__init__)
OLD_CBF_PAPER = dict(
    predict_latency=False, recovery=False, goal_aware_margin=False, maze=False, reference="clf", quadrotor=False
)
OLD_HJ_PAPER = dict(order=1, rk=2, rule="value", margin=0.0, standstill_lookup=False, maze=False, quadrotor=False)


def test_the_defaults_and_presets_are_the_former_arguments():
    assert dataclasses.asdict(CBFSettings()) == OLD_CBF and dataclasses.asdict(HJSettings()) == OLD_HJ
    assert CBF_PRESETS["cbf-paper"] == CBFSettings(**OLD_CBF_PAPER) == CBFSettings(**(OLD_CBF | OLD_CBF_PAPER))
    assert HJ_PRESETS["hj-paper"] == HJSettings(**OLD_HJ_PAPER)
    assert CBFPaperGuardian().settings == CBF_PRESETS["cbf-paper"] and CBFGuardian().settings == CBF_PRESETS["cbf"]
    assert HJPaperGuardian().settings == HJ_PRESETS["hj-paper"] and HJGuardian().settings == HJ_PRESETS["hj"]
    p = HJPaperGuardian()
    assert (p.order, p.rk, p.rule, p.margin, p.standstill_lookup) == (1, 2, "value", 0.0, False)
    c = CBFPaperGuardian()
    assert (c.predict_latency, c.recovery, c.goal_aware_margin, c.reference, c.served()) == (
        False,
        False,
        False,
        "clf",
        (),
    )


def test_keyword_arguments_build_the_settings_over_the_preset():
    g = CBFPaperGuardian(p1=0.5, recovery=True)
    assert g.settings == CBFSettings(**(OLD_CBF_PAPER | {"p1": 0.5, "recovery": True})) and (g.p1, g.recovery) == (
        0.5,
        True,
    )
    assert CBFGuardian(CBFSettings.preset("cbf-paper"), max_obstacles=8).settings == CBFSettings.preset(
        "cbf-paper", max_obstacles=8
    )
    h = make_guardian("hj-paper", horizon=2.0, threads=1)  # as --agent-opt hj-paper.horizon=2 builds it
    assert h.settings == HJSettings.preset("hj-paper", horizon=2.0, threads=1) and (h.horizon, h.threads) == (2.0, 1)
    assert CBFSettings(u1_bounds=[-1, 1]).u1_bounds == (-1.0, 1.0) and HJSettings(grid_n=[9.0, 9, 8, 5]).grid_n == (
        9,
        9,
        8,
        5,
    )


def test_the_constructors_show_every_setting_in_their_signature():
    for cls, settings, preset in ((CBFGuardian, CBFSettings, "cbf"), (HJGuardian, HJSettings, "hj")):
        params = inspect.signature(cls).parameters
        assert list(params)[1:] == list(settings.names()) and list(params)[0] == "settings"
        assert all(params[n].default == getattr(settings.PRESETS[preset], n) for n in settings.names())
    assert accepts_argument(HJGuardian, "threads") and accepts_argument(HJPaperGuardian, "threads")
    assert not accepts_argument(CBFGuardian, "threads")


@pytest.mark.parametrize(
    "cls, changes, message",
    [
        (CBFSettings, {"p1": 0.0}, "p1 (class-K gain) must be a finite number > 0.0, got 0.0"),
        (CBFSettings, {"inflation": 0.9}, "inflation must be >= 1 (1 = the obstacle itself), got 0.9"),
        (CBFSettings, {"lambda_v": math.inf}, "lambda_v must be a finite number > 0.0, got inf"),
        (CBFSettings, {"v_stuck": -1}, "v_stuck must be a finite number >= 0.0, got -1"),
        (CBFSettings, {"u1_bounds": (0.1, 0.2)}, "u1_bounds must contain 0, got (0.1, 0.2)"),
        (
            CBFSettings,
            {"u2_bounds": (0.0, 1.0)},
            "u2_bounds must allow braking and accelerating (min < 0 < max), got (0.0, 1.0)",
        ),
        (CBFSettings, {"max_obstacles": 2.5}, "max_obstacles must be an integer >= 0, got 2.5"),
        (CBFSettings, {"reference": "goal"}, "reference must be one of ('nominal', 'clf')"),
        (HJSettings, {"horizon": -1.0}, "horizon must be a finite number > 0.0, got -1.0"),
        (HJSettings, {"rule": "fast"}, "rule must be one of ('distance', 'gradient', 'value'), got 'fast'"),
        (HJSettings, {"mode": "reach"}, "mode must be 'avoid' or 'reach_avoid', got 'reach'"),
        (HJSettings, {"delay": -1}, "delay must be an integer >= 0 (laps between a decision and its effect), got -1"),
        (HJSettings, {"threads": 0}, "threads must be an integer >= 1 (or None), got 0"),
        (HJSettings, {"grid_n": (9, 9, 8, 5), "grid": object()}, "give grid or grid_n, not both"),
        (HJSettings, {"backend": "gpu"}, "backend must be one of ('auto', 'numpy', 'numba'), got 'gpu'"),
        (HJSettings, {"disturbance": -0.1}, "disturbance must be a finite number >= 0.0, got -0.1"),
    ],
)
def test_a_bad_setting_is_refused_naming_it_and_the_value(cls, changes, message):
    with pytest.raises(ValueError) as e:
        cls(**changes)
    assert str(e.value).startswith(message)
    with pytest.raises(ValueError) as e:  # the same check through the guardian and a preset
        (CBFGuardian if cls is CBFSettings else HJGuardian)(**changes)
    assert str(e.value).startswith(message)


def test_settings_are_frozen_and_unknown_names_are_refused_by_name():
    s = CBFSettings()
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.p1 = 1.0
    with pytest.raises(TypeError, match=r"unknown CBFSettings setting\(s\) \['gain'\]; the settings are: p1, p2, "):
        CBFGuardian(gain=1.0)
    with pytest.raises(ValueError, match=r"unknown HJSettings preset 'hj-fast'; the presets are: \['hj', 'hj-paper'\]"):
        HJSettings.preset("hj-fast")
    assert s.replace() is s and s.replace(p2=0.5) == CBFSettings(p2=0.5)
