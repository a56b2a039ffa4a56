"""The baseline guardians' contract, pinned where the broader tests in test_guardians.py leave room."""

import numpy as np
import pytest

from rmm_envs.autonomy import GuardianActionSpace, SafeDefault
from rmm_envs.systems.dubins4d.dynamics import Dubins4D, FullBraking
from rmm_envs.systems.dubins4d.env import CONTROLS
from rmm_guardians.baselines import BrakesGuardian, RandomGuardian

DUBINS = GuardianActionSpace.for_dynamics(Dubins4D(), CONTROLS, safe_default=FullBraking())


class ReadsObservation(SafeDefault):
    """A safe default that steers by the observation and takes no options (as the maze car's)."""

    description = "steer by the observation"

    def policy(self, space, rng, **options):
        self.check_options(options)
        return lambda obs: np.array([float(obs[0]), space.control_low[1]])


def space(safe_default):
    return GuardianActionSpace(("turn", "speed"), [-1.0, -2.0], [1.0, 2.0], safe_default=safe_default)


def test_brakes_hands_the_observation_to_the_safe_default():
    g = BrakesGuardian()
    g.reset(seed=0, action_space=space(ReadsObservation()))
    for x in (0.5, -0.25):
        a = g.act(np.array([x, 9.0]), {})
        assert a["active_ctrl"] == 1 and a["turn"][0] == np.float32(x) and a["speed"][0] == -2.0


def test_brakes_turn_random_is_the_dubins4d_default_and_both_choices_are_accepted():
    a, b = BrakesGuardian(), BrakesGuardian(turn="random")
    for g in (a, b):
        g.reset(seed=7, action_space=DUBINS)
    assert a.act(None, {})["turnrate_ctrl"][0] == b.act(None, {})["turnrate_ctrl"][0] != 0.0
    z = BrakesGuardian(turn="zero")
    z.reset(seed=7, action_space=DUBINS)
    assert z.act(None, {})["turnrate_ctrl"][0] == 0.0


def test_brakes_refuses_before_any_episode_naming_what_is_missing():
    g = BrakesGuardian()
    with pytest.raises(
        ValueError, match=r"guardian 'brakes'.*states none \(GuardianActionSpace\(safe_default=\.\.\.\)"
    ):
        g.check_spaces(None, space(None))
    # a turn choice on a safe default that has none: refused by check_spaces itself, naming the guardian
    with pytest.raises(ValueError, match=r"guardian 'brakes': the safe default .*steer by the observation.*'turn'"):
        BrakesGuardian(turn="zero").check_spaces(None, space(ReadsObservation()))
    with pytest.raises(ValueError, match=r"guardian 'brakes': .*'turn'"):
        BrakesGuardian(turn="zero").reset(seed=0, action_space=space(ReadsObservation()))
    BrakesGuardian().check_spaces(None, space(ReadsObservation()))  # no turn given: accepted


def test_random_accepts_the_probability_bounds():
    never, always = RandomGuardian(p_active=0.0), RandomGuardian(p_active=1.0)
    for g in (never, always):
        g.reset(seed=3, action_space=DUBINS)
    assert {never.act(None, {})["active_ctrl"] for _ in range(200)} == {0}
    assert {always.act(None, {})["active_ctrl"] for _ in range(200)} == {1}
    for bad in (-0.01, 1.01, float("nan")):
        with pytest.raises(ValueError, match="p_active"):
            RandomGuardian(p_active=bad)
