"""Helpers that the driver and a guardian share have one compiled owner, below both."""

from __future__ import annotations

import math

from hypothesis import example, given, settings
from hypothesis import strategies as st

from rmm_envs.systems.dubins4d import dynamics as dubins4d

ANGLE = st.floats(-math.pi, math.pi, allow_nan=False)


def test_desired_heading_is_compiled_once_and_used_by_the_driver_and_the_cbf_rows():
    from rmm_envs.systems.dubins4d import driver
    from rmm_guardians.cbf import barrier

    assert barrier._desired_heading is driver._desired_heading is dubins4d.desired_heading_compiled
    assert driver.desired_heading is dubins4d.desired_heading  # the Python function, re-exported


@settings(deadline=None)  # the first call compiles
@given(ANGLE, ANGLE)
@example(-0.5, math.pi)  # the branch cuts
@example(0.5, -math.pi)
@example(-math.pi, 1.0)
def test_the_compiled_desired_heading_equals_the_python_one(theta, goal):
    assert dubins4d.desired_heading_compiled(theta, goal) == dubins4d.desired_heading(theta, goal)
