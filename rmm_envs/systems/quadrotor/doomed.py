"""The quadrotor's doomed-start test (its spec's ``doomed_test``): a start at rest is avoidable by
hovering."""

from __future__ import annotations

import numpy as np

from rmm_envs.starts import StartAssessment

__all__ = ["QUADROTOR_METHOD", "quadrotor_test"]


#: the method name stored with each quadrotor assessment
QUADROTOR_METHOD = "at-rest:hover"


def quadrotor_test(env) -> StartAssessment:
    """The doomed test of a quadrotor guardian env right after ``reset``: a start at rest (every
    generated start is level and still, clear of the room by 0.2 m) is avoidable, since holding
    the hover-and-level command keeps the body where it is (the safe default, which never
    collided in the 2,048 episodes of the quadrotor's Table I); a given start that moves is not
    assessed."""
    state = np.asarray(env.unwrapped.true_state, float)
    if np.abs(state[7:13]).max() > 1e-9:
        return StartAssessment(None, "")
    return StartAssessment(False, QUADROTOR_METHOD)
