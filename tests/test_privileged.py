"""rmm_guardians.privileged: the one lap measurement and non-finite-state guard that every privileged
guardian (cbf and hj on each system) uses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from rmm_guardians.cbf.guardian import CBFGuardian
from rmm_guardians.cbf.maze import MazeCBFGuardian
from rmm_guardians.cbf.quadrotor import QuadrotorCBFGuardian
from rmm_guardians.hj.guardian import HJGuardian
from rmm_guardians.hj.maze import MazeHJGuardian
from rmm_guardians.hj.quadrotor import QuadrotorHJGuardian
from rmm_guardians.privileged import DEFAULT_LAP, PrivilegedGuardian


class Probe(PrivilegedGuardian):
    name = "probe"

    def __init__(self, lap=None):
        super().__init__()
        self.lap = lap
        self._counts = {"nan_states": 0}


def test_every_privileged_guardian_shares_the_base():
    for cls in (CBFGuardian, MazeCBFGuardian, QuadrotorCBFGuardian, HJGuardian, MazeHJGuardian, QuadrotorHJGuardian):
        assert issubclass(cls, PrivilegedGuardian) and cls.privileged and cls.observation_type == "global", cls
        for method in ("measure_lap", "finite_state", "start_laps", "_state_and_lap"):
            assert method not in vars(cls), (cls, method)  # inherited, not a copy


def test_laps_measured_from_the_first_decision():
    g = Probe()
    g.start_laps()
    assert g.current_lap() == DEFAULT_LAP == 0.1
    g.measure_lap({"sim_time": 2.0})  # the first decision: nothing to measure against yet
    assert g._measured_lap is None and g.current_lap() == 0.1
    g.measure_lap({"sim_time": 2.25})
    assert g._measured_lap == 0.25 and g.current_lap() == 0.25
    g.measure_lap({})  # no time reported: nothing moves
    g.measure_lap({"sim_time": 2.25})  # time did not advance: the lap stays
    assert g._measured_lap == 0.25 and g._last_time == 2.25
    g.measure_lap({"sim_time": 2.0})  # time went back (a reset the guardian missed): the clock follows
    assert g._last_time == 2.0 and g._measured_lap == 0.25
    g.measure_lap({"sim_time": 2.5})
    assert g._measured_lap == 0.5
    assert Probe(lap=0.3).current_lap() == 0.3  # a fixed lap wins over any measurement


def test_laps_measured_from_the_reset_with_a_guess():
    g = Probe()
    g.start_laps(0.07, since=1.0)
    assert g.current_lap() == 0.07 and g._last_time == 1.0
    g.measure_lap({"sim_time": 1.125})
    assert g._measured_lap == 0.125


@given(st.lists(st.floats(0.0, 1e6, allow_nan=False), min_size=2, max_size=20))
def test_the_measured_lap_is_the_last_positive_gap(times):
    g = Probe()
    g.start_laps()
    expected = None
    for a, b in zip(times, times[1:], strict=False):  # consecutive pairs: one fewer than times
        if b > a:
            expected = float(b - a)
    for t in times:
        g.measure_lap({"sim_time": t})
    assert g._measured_lap == expected


def test_the_state_guard_counts_what_it_refuses():
    g = Probe()
    assert g.finite_state(np.array([1.0, 2.0, 3.0])) and g._counts["nan_states"] == 0
    for bad, size in (([1.0, math.nan], None), ([math.inf, 0.0], None), ([1.0, 2.0], 3)):
        assert not g.finite_state(np.array(bad), size)
    assert g._counts["nan_states"] == 3
    g._privileged = lambda: {"state": [1, 2], "sim_time": 0.5}
    g.start_laps()
    s = g._state_and_lap()
    assert s.dtype == np.float64 and s.tolist() == [1.0, 2.0] and g._last_time == 0.5


@pytest.mark.parametrize("cls", [CBFGuardian, HJGuardian])
def test_a_nan_state_brakes_fully_and_is_counted(cls, tmp_path):
    from rmm_envs.autonomy import GuardianActionSpace
    from rmm_envs.systems.dubins4d.dynamics import CONTROLS, Dubins4D

    space = GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, dynamics_name="dubins4d")
    g = cls(cache_dir=tmp_path, grid_n=(9, 9, 8, 5), horizon=0.5) if cls is HJGuardian else cls(reference="clf")
    box = {
        "obstacles": np.array([[5.0, 0.0, 1.0]]),
        "goal": np.array([9.0, 9.0, 0.5]),
        "state": np.array([0.0, 0.0, 0.0, 1.0]),
        "sim_time": 0.0,
    }
    g.reset(seed=0, privileged=lambda: box, action_space=space)
    box["state"] = np.array([0.0, math.nan, 0.0, 1.0])
    a = g.act(None, {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == 0.0 and a["accel_ctrl"][0] == space.control_low[1]
    assert g.stats()["nan_states"] == 1
