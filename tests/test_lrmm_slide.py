"""lrmm's ``Slide`` strategy and ``RatedDriver``'s still and stay (``rmm_guardians.lrmm.strategies``,
``rmm_guardians.lrmm.nominal``): the variants of the driver's velocity command, the take-over test,
and the quadrotor guardian on a hand-built model whose risks are computed by hand below."""

import math

import numpy as np
import pytest

from rmm_envs.autonomy import GuardianActionSpace, ObservationBox
from rmm_guardians.lrmm.decision import decision_path, read_decision, set_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.nominal import driver_at_risk
from rmm_guardians.lrmm.strategies import (
    SLIDE_MOVES,
    SLIDE_TURNS,
    Commit,
    RatedDriver,
    SafestCandidate,
    Slide,
    driver,
)
from tests.test_lrmm import SPACES as D4_SPACES
from tests.test_lrmm_filter import QUAD, QUAD_CONTROLS, speed_model

LOW, HIGH = [-2.0, -2.0, -1.0, -1.0], [2.0, 2.0, 1.0, 1.0]  # the quadrotor's command box
HEAD = [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [-1.5, 0.0, 0.0, 0.0], [-1.0, 0.0, 1.0, 0.0]]
NOMINAL = [1.2, -0.4, -0.5, 0.3]  # forward and right, descending, turning left


def sig(z):
    return 1.0 / (1.0 + math.exp(-z))


def test_the_shipped_moves_climb_at_full_half_and_no_horizontal_speed():
    assert SLIDE_MOVES == (((1.0, 0.0), 1.0, "climb"), ((1.0, 0.0), 0.5, "climb"), ((1.0, 0.0), 0.0, "climb"))


def bound_slide():
    """The quadrotor guardian's Slide, bound to its controls and their box (as at reset)."""
    g = LRMMGuardian(quad_model(), threshold=0.2, strategies="RatedDriver(margin=0.15), SafestCandidate, Slide")
    g.reset(seed=0, **SPACES)
    (s,) = [x for x in g.strategies if isinstance(x, Slide)]
    return s


def test_variants_by_hand_nearest_first_clipped_without_the_driver_control(monkeypatch):
    s = bound_slide()
    # gaps 1.5, sqrt(0.36 + 0.04 + 2.25) and sqrt(1.44 + 0.16 + 2.25); the yaw rate stays the driver's
    assert s.variants(NOMINAL) == [[1.2, -0.4, 1.0, 0.3], [0.6, -0.2, 1.0, 0.3], [0.0, 0.0, 1.0, 0.3]]
    assert s.variants([0.0, 0.0, 1.0, -0.2]) == []  # already climbing in place: no variant differs
    # other moves (the module's table, read at each call): 90 degrees left (gap sqrt 2), half speed (gap 0.5),
    # twice the speed clipped to 2 with half the climb (gap sqrt(1 + 0.0625)): nearest first
    moves = (((0.0, 1.0), 1.0, 1.0), ((1.0, 0.0), 0.5, 1.0), ((1.0, 0.0), 2.0, 0.5))
    monkeypatch.setattr(driver, "SLIDE_MOVES", moves)
    assert s.variants([1.0, 0.0, 0.5, 0.0]) == [[0.5, 0.0, 0.5, 0.0], [2.0, 0.0, 0.25, 0.0], [0.0, 1.0, 0.5, 0.0]]


def test_turn_adds_the_command_turned_aside_and_backing_off_after_the_climbs():
    assert SLIDE_TURNS == (((0.0, 1.0), 1.0, "climb"), ((0.0, -1.0), 1.0, "climb"), ((-1.0, 0.0), 0.5, "climb"))
    s = bound_slide()
    s.turn = True
    # after the three climbs (gaps 1.5, 1.63, 1.96): a quarter left (0.4, 1.2) and right (-0.4, -1.2), both
    # at gap sqrt(0.64 + 2.56 + 2.25) = 2.33 (left first), then backing off at half speed, gap sqrt(5.85) = 2.42
    assert s.variants(NOMINAL) == [
        [1.2, -0.4, 1.0, 0.3],
        [0.6, -0.2, 1.0, 0.3],
        [0.0, 0.0, 1.0, 0.3],
        [0.4, 1.2, 1.0, 0.3],
        [-0.4, -1.2, 1.0, 0.3],
        [-0.6, 0.2, 1.0, 0.3],
    ]
    assert s.variants([0.0, 0.0, 0.2, 0.0]) == [[0.0, 0.0, 1.0, 0.0]]  # hovering: every turn is the same climb


def test_escape_moves_down_the_rated_risk_when_no_variant_is_safe():
    # threshold 0.001: no variant is rated at or below it; the lowest is backing off at half speed, climbing,
    # sigmoid(-1.2 - 2 + 10 - 13) = 0.0020, below the head's climb in place that SafestCandidate chose (0.0067)
    assert rating(-0.6, 1.0) == pytest.approx(0.00203, abs=1e-5) and rating(0.0, 1.0) == pytest.approx(0.0067, abs=1e-4)
    rule = (RatedDriver(margin=0.15), Commit(steps=0), SafestCandidate())
    for escape, expected in ((True, [1, -0.6, 0.2, 1.0, 0.3]), (False, [1, 0.0, 0.0, 1.0, 0.0])):
        g = LRMMGuardian(quad_model(), threshold=0.001, strategies=rule + (Slide(turn=True, escape=escape),))
        g.reset(seed=0, **SPACES)
        assert step(g, NOMINAL) == expected
    # without turn the climbs are all rated at least the climb in place: the control before is kept
    g = LRMMGuardian(quad_model(), threshold=0.001, strategies=rule + (Slide(escape=True),))
    g.reset(seed=0, **SPACES)
    assert step(g, NOMINAL) == [1, 0.0, 0.0, 1.0, 0.0]


def test_turn_bends_the_command_aside_when_no_climb_is_rated_safe():
    # threshold 0.005: no climb is (climbing in place 0.0067); a quarter left is rated sigmoid(-4.2) = 0.015, a
    # quarter right sigmoid(-5.8) = 0.0030: the nearest safe variant, before the head's candidate
    assert rating(0.4, 1.0) == pytest.approx(0.0148, abs=1e-4) and rating(-0.4, 1.0) == pytest.approx(0.0030, abs=1e-4)
    rule = (RatedDriver(margin=0.15), Commit(steps=0), SafestCandidate(), Slide(turn=True))
    g = LRMMGuardian(quad_model(), threshold=0.005, strategies=rule)
    g.reset(seed=0, **SPACES)
    assert step(g, NOMINAL) == [1, -0.4, -1.2, 1.0, 0.3]
    assert step(guard(threshold=0.005), NOMINAL) == [1, 0.0, 0.0, 1.0, 0.0]  # without turn: the head's


def test_slide_turn_spec_round_trips_and_its_default_stays_out_of_stored_specs():
    assert (Slide().spec(), Slide(turn=True).spec()) == ("Slide()", "Slide(turn=True)")
    assert Slide(turn=True).params() == {"turn": True, "escape": False} and Slide(turn=True) != Slide()
    assert (
        Slide(escape=True).spec() == "Slide(escape=True)"
        and Slide(True, True).spec() == "Slide(turn=True, escape=True)"
    )
    with pytest.raises(ValueError, match="Slide turn must be True or False, got 'yes'"):
        LRMMGuardian(quad_model(), threshold=0.2, strategies="Slide(turn='yes')")
    with pytest.raises(ValueError, match="Slide escape must be True or False, got 1"):
        LRMMGuardian(quad_model(), threshold=0.2, strategies="Slide(escape=1)")


def test_slide_needs_the_three_velocity_controls():
    g = LRMMGuardian(speed_model(), threshold=0.5, strategies="RatedDriver, SafestCandidate, Slide")  # Dubins4D
    with pytest.raises(
        ValueError,
        match=r"guardian 'lrmm': strategy Slide bends a velocity command: it needs the controls .*vup_ctrl.*got "
        r"\('turnrate_ctrl', 'accel_ctrl'\)",
    ):
        g.check_spaces(D4_SPACES["observation_space"], D4_SPACES["action_space"])


@pytest.mark.parametrize(
    "rated, still, holding, expected",
    [
        ([0.30, 0.27, 0.20, 0.10], None, False, True),  # the best candidate saves 0.20 > 0.15
        ([0.30, 0.27, 0.20, 0.16], None, False, False),  # it saves 0.14; no still test
        ([0.30, 0.27, 0.20, 0.16], None, True, True),  # in control, staying while above the threshold
        ([0.30, 0.24, 0.20, 0.16], 0.05, False, True),  # holding still saves 0.06 > 0.05
        ([0.30, 0.27, 0.20, 0.16], 0.05, False, False),  # it saves 0.03
        ([0.20, 0.00, 0.00, 0.00], 0.05, True, False),  # at the threshold: never
    ],
)
def test_take_over_test_by_hand(rated, still, holding, expected):
    assert driver_at_risk(rated, 0.2, 0.15, still, holding) is expected


def quad_model(head=(0.3, 0.1, 0.5, 0.2)):
    """Unit 0 = sigmoid(relu(2 vf - 2 vup + 10) - 13) of the measured forward and up velocity (obs 14
    and 16); the head's units are the constants ``head`` (hover, climb, back off, back off and climb)."""
    W0 = np.zeros((1, 23))
    W0[0, 14], W0[0, 16] = 2.0, -2.0
    W1 = np.array([[1.0], [0.0], [0.0], [0.0], [0.0]])
    b1 = np.array([-13.0] + [math.log(p / (1 - p)) for p in head])
    meta = {
        "env_id": "QuadrotorRoomGuarded-v0",
        "obs_dim": 23,
        "features": list(range(23)),
        "hidden": [1],
        "activation": "relu",
        "output_bias": True,
        "candidates": HEAD,
        "candidate_hold": 1.0,
    }
    return LRMMModel([(W0, np.array([10.0])), (W1, b1)], np.zeros(23), np.ones(23), meta)


def rating(vf, vup):
    return sig(max(2 * vf - 2 * vup + 10, 0.0) - 13)


SPACES = {
    "observation_space": ObservationBox(np.full(23, -np.inf), np.full(23, np.inf), QUAD),
    "action_space": GuardianActionSpace(QUAD_CONTROLS, LOW, HIGH),
}
OBS = np.zeros(23)


def guard(threshold=0.2, commit=0, margin=0.15, still=None, stay=True, slide=True):
    """The quadrotor's stored rule: RatedDriver, Commit, the head's safest candidate, then Slide."""
    rule = (RatedDriver(margin=margin, still=still, stay=stay), Commit(steps=commit), SafestCandidate())
    g = LRMMGuardian(quad_model(), threshold=threshold, strategies=rule + ((Slide(),) if slide else ()))
    g.reset(seed=0, **SPACES)
    return g


def command(a):
    return [a["active_ctrl"]] + [round(float(a[c][0]), 12) for c in QUAD_CONTROLS]


def step(g, u):
    return command(g.act(OBS, {"nominal_control": np.array(u)}))


def test_guardian_slides_keeps_control_while_the_driver_is_risky_and_hands_back_when_safe():
    g = guard()
    assert rating(1.2, -0.5) == pytest.approx(0.599, abs=1e-3) and rating(1.2, 1.0) == pytest.approx(0.069, abs=1e-3)
    # the driver's command is rated 0.599, the best candidate (back off and climb) 0.0009: take control with the
    # nearest variant rated at most 0.2, climbing at the driver's horizontal velocity and yaw rate (0.069)
    assert step(g, NOMINAL) == [1, 1.2, -0.4, 1.0, 0.3]
    assert g.signals()["risk_driver"] == pytest.approx(rating(1.2, -0.5))
    # the driver faster, rated sigmoid(0.7) = 0.67: still in control, climbing (sigmoid(-2.3) = 0.091)
    assert step(g, [1.35, 0.0, -0.5, 0.0]) == [1, 1.35, 0.0, 1.0, 0.0]
    assert step(g, [0.5, 0.0, 0.0, 0.0]) == [0, 0.0, 0.0, 0.0, 0.0]  # rated 0.119: handed back (commit 0)


def test_commit_holds_the_slide_after_the_driver_is_rated_safe():
    g = guard(commit=2)
    safe = [0.5, 0.0, 0.0, 0.0]  # rated 0.119; its climbing variant [0.5, 0, 1, 0] 0.018
    assert [step(g, u)[0] for u in (NOMINAL, safe, safe, safe)] == [1, 1, 1, 0]
    g.reset(seed=0, **SPACES)
    assert [step(g, u) for u in (NOMINAL, safe)] == [[1, 1.2, -0.4, 1.0, 0.3], [1, 0.5, 0.0, 1.0, 0.0]]


def test_the_nearest_safe_variant_then_the_head_when_none_is_safe():
    # threshold 0.05: the full-speed climb (0.069) is above it, the half-speed one (sigmoid(-3.8) = 0.022) is not
    assert step(guard(threshold=0.05), NOMINAL) == [1, 0.6, -0.2, 1.0, 0.3]
    # threshold 0.005: even climbing in place is rated 0.0067: the head's safest candidate (climb, 0.1), as is
    assert step(guard(threshold=0.005), NOMINAL) == [1, 0.0, 0.0, 1.0, 0.0]
    # without slide: the head's safest candidate
    assert step(guard(slide=False), NOMINAL) == [1, 0.0, 0.0, 1.0, 0.0]


def test_still_takes_control_when_the_driver_adds_risk_to_holding_still():
    # a margin no candidate can save: only the still test acts; holding still is rated sigmoid(-3) = 0.047
    assert step(guard(margin=0.99, still=0.5), NOMINAL)[0] == 1  # 0.599 - 0.047 = 0.55 > 0.5
    assert step(guard(margin=0.99, still=0.6), NOMINAL)[0] == 0
    assert step(guard(margin=0.99), NOMINAL)[0] == 0  # no still test


def test_without_stay_the_guardian_hands_back_once_the_take_over_test_fails():
    u3 = [1.0, 0.0, -0.3, 0.0]  # rated sigmoid(-0.4) = 0.401 > 0.2, but only 0.354 above holding still
    assert rating(1.0, -0.3) == pytest.approx(0.401, abs=1e-3)
    staying, leaving = guard(margin=0.99, still=0.5), guard(margin=0.99, still=0.5, stay=False)
    assert [step(staying, u)[0] for u in (NOMINAL, u3)] == [1, 1]
    assert [step(leaving, u)[0] for u in (NOMINAL, u3)] == [1, 0]


def test_bad_slide_still_and_stay_are_named():
    m = quad_model()
    for spec, match in (
        (
            "Slide(x=1)",
            r"strategy 'Slide\(x=1\)': .*unexpected keyword argument 'x'; its parameters: turn, escape",
        ),
        ("RatedDriver(stay='no')", "RatedDriver stay must be True or False, got 'no'"),
        ("RatedDriver(still=-0.1)", r"RatedDriver still must be a finite number >= 0.0, got -0.1"),
        ("RatedDriver(still=1e999)", "RatedDriver still must be"),
        ("Slide, Slide", "each strategy may appear once"),
    ):
        with pytest.raises(ValueError, match=match):
            LRMMGuardian(m, threshold=0.2, strategies=spec)
    # Slide reads the driver's control itself: without RatedDriver (the former trigger='driver') the state
    # risk decides when, and Slide what
    alone = LRMMGuardian(m, threshold=0.2, strategies="SafestCandidate, Slide")
    alone.reset(seed=0, **SPACES)
    fast = OBS.copy()
    fast[14], fast[16] = 1.2, -0.5  # measured: the driver's command, rated 0.599 as the state risk
    assert step_at(alone, fast, NOMINAL) == [1, 1.2, -0.4, 1.0, 0.3]
    assert "risk_driver" not in alone.signals()
    no_climb = LRMMGuardian(m, threshold=0.2, strategies="RatedDriver, SafestCandidate, Slide")
    with pytest.raises(ValueError, match="strategy Slide bends a velocity command"):
        no_climb.reset(
            seed=0,
            observation_space=SPACES["observation_space"],
            action_space=GuardianActionSpace(("vforward_ctrl", "vleft_ctrl", "yawrate_ctrl", "vz"), LOW, HIGH),
        )


def step_at(g, obs, u):
    return command(g.act(obs, {"nominal_control": np.array(u)}))


def test_stored_slide_still_and_stay_round_trip(tmp_path):
    p = quad_model().save(tmp_path / "q.npz")
    spec = "RatedDriver(margin=0.15, still=0.05, stay=False), Commit(steps=20), SafestCandidate, Slide"
    set_decision(p, 0.2, spec, "a test")
    d = read_decision(decision_path(p))
    assert (d.threshold, d.strategies, d.chosen_by) == (
        0.2,
        "RatedDriver(margin=0.15, still=0.05, stay=False), Commit(steps=20), SafestCandidate(), Slide()",
        {"how": "a test"},
    )
    g = LRMMGuardian(p)
    rd = g.strategies[0]
    assert (type(rd), rd.margin, rd.still, rd.stay, g.strategies[-1]) == (RatedDriver, 0.15, 0.05, False, Slide())
    # arguments override the file
    kept = LRMMGuardian(p, strategies="-Slide, +RatedDriver(margin=0.15, still=0.05, stay=True)")
    assert kept.strategies == (RatedDriver(0.15, 0.05, True), Commit(steps=20), SafestCandidate())
    from rmm_guardians.lrmm.decision import main as decision_main

    cli = "RatedDriver(margin=0.15, still=0.05), Commit(steps=20), SafestCandidate, Slide"
    assert decision_main([str(p), "--threshold", "0.2", "--strategies", cli, "--chosen-by", "t"]) == 0
    stored = read_decision(decision_path(p)).strategies
    assert stored.startswith("RatedDriver(margin=0.15, still=0.05, stay=True), ") and stored.endswith(", Slide()")
    assert decision_main([str(p), "--threshold", "0.2", "--strategies", "Slide(climb=True)", "--chosen-by", "t"]) == 2
