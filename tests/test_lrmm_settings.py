"""rmm_guardians.lrmm.settings: the lrmm guardian's settings and presets, and one precedence for its
threshold and strategies (argument > the model file's stored decision > the shipped entry's > the
paper's 0.85 and no strategies)."""

from __future__ import annotations

import math

import pytest

from rmm_guardians.lrmm.settings import (
    DECISION_KEYS,
    LRMM_PRESETS,
    PAPER_THRESHOLD,
    LRMMSettings,
    check_threshold,
    decision_threshold,
    stored_decision,
    stored_strategies,
)
from rmm_guardians.lrmm.shipped import Shipped
from rmm_guardians.lrmm.strategies import STRATEGIES, BrakeTurn, Commit, Restart, SafestCandidate

SHIP = Shipped({"act": "x.npz"}, decision={"threshold": 0.6, "strategies": ["Commit(steps=3)"], "chosen_by": "a test"})


@pytest.mark.parametrize(
    "bad, message",
    [
        (True, "threshold must be a number in [0, 1], got True"),
        ("0.5", "threshold must be a number in [0, 1], got '0.5'"),
        (1.5, "threshold must be in [0, 1], got 1.5"),
        (-0.1, "threshold must be in [0, 1], got -0.1"),
        (math.nan, "threshold must be in [0, 1], got nan"),
    ],
)
def test_a_bad_threshold_argument_is_refused_by_value(bad, message):
    with pytest.raises(ValueError) as e:
        check_threshold(bad)
    assert str(e.value) == message
    with pytest.raises(ValueError):
        decision_threshold(bad, {"threshold": 0.3}, "m.npz")
    with pytest.raises(ValueError) as e:
        LRMMSettings(threshold=bad)
    assert str(e.value) == message


def test_the_stored_decision_is_the_model_files_else_the_shipped_entrys_for_its_own_model():
    own = {"threshold": 0.2, "strategies": ["Commit(steps=1)"]}
    assert stored_decision({"decision": own}, SHIP, model_given=False) is own  # the file wins over the table
    assert stored_decision({}, SHIP, model_given=False) is SHIP.decision
    assert stored_decision({}, SHIP, model_given=True) is None  # a model given by path: no shipped decision
    assert stored_decision({"decision": own}, None, model_given=True) is own
    assert stored_decision({}, None, model_given=False) is None


def test_the_threshold_precedence():
    assert decision_threshold(0.4, {"threshold": 0.6}, "m.npz") == (0.4, "argument")
    assert decision_threshold(0, {"threshold": 0.6}, "m.npz") == (0.0, "argument")  # 0 is a value, not "not given"
    assert decision_threshold(None, {"threshold": 0.6}, "m.npz") == (0.6, "stored decision")
    assert decision_threshold(None, {"strategies": []}, "m.npz") == (PAPER_THRESHOLD, "paper") == (0.85, "paper")
    assert decision_threshold(None, None, "m.npz") == (0.85, "paper")
    with pytest.raises(ValueError, match=r"^m.npz: stored decision threshold must be in \[0, 1\], got 1.2$"):
        decision_threshold(None, {"threshold": 1.2}, "m.npz")


def test_the_stored_strategies_and_their_refusals():
    assert stored_strategies(None, "m.npz") == () and stored_strategies({}, "m.npz") == ()
    assert stored_strategies({"threshold": 0.3}, "m.npz") == ()  # no strategies stored: the core alone
    assert stored_strategies(
        {"threshold": 0.3, "strategies": ["SafestCandidate()", "Commit(steps=18)", "Restart(speed=0.3)"]}, "m.npz"
    ) == (SafestCandidate(), Commit(steps=18), Restart(speed=0.3))
    assert DECISION_KEYS == ("threshold", "strategies", "chosen_by")
    with pytest.raises(ValueError) as e:
        stored_strategies({"threshold": 0.3, "commit": 18, "action": "head"}, "m.npz")
    assert str(e.value) == (
        "m.npz: stored decision has unknown key(s) ['action', 'commit']; a decision holds threshold, strategies, "
        "chosen_by (rewrite it with python -m rmm_guardians.lrmm.decision)"
    )
    with pytest.raises(ValueError, match=r"^m.npz: stored decision: unknown strategy 'Steer'; the strategies are: "):
        stored_strategies({"strategies": ["Steer()"]}, "m.npz")
    for bad in ("Commit(steps=1)", [3], {"Commit": 1}):
        with pytest.raises(ValueError, match=r"^m.npz: stored decision strategies must be a list of spec strings"):
            stored_strategies({"strategies": bad}, "m.npz")
    with pytest.raises(ValueError, match=r"^m.npz: stored decision: .*Commit steps must be an integer >= 0"):
        stored_strategies({"strategies": ["Commit(steps=-2)"]}, "m.npz")


def test_the_guardian_reports_where_its_threshold_came_from():
    from rmm_guardians.lrmm.guardian import LRMMGuardian, LRMMPaperGuardian
    from rmm_guardians.lrmm.model import load_model

    g = LRMMGuardian()
    stored = g.model.meta.get("decision") or {}
    assert (g.threshold, g.threshold_source) == (float(stored["threshold"]), "stored decision")
    assert LRMMGuardian(threshold=0.5).threshold_source == "argument"
    assert (LRMMPaperGuardian().threshold, LRMMPaperGuardian().threshold_source) == (0.85, "argument")
    bare = load_model(g.model.path)
    bare.meta.pop("decision", None)
    with pytest.warns(UserWarning, match="has no 'decision' threshold: using the paper's 0.85"):
        h = LRMMGuardian(model=bare)
    assert (h.threshold, h.threshold_source, h.strategies) == (0.85, "paper", ())  # and the core alone


def test_the_ends_of_the_threshold_range_are_values():
    for t in (0, 0.0, 1, 1.0):
        assert check_threshold(t) == float(t)
        assert decision_threshold(None, {"threshold": t}, "m.npz") == (float(t), "stored decision")
    for bad in (1.0000001, -1e-9):
        with pytest.raises(ValueError, match="stored decision threshold must be in"):
            decision_threshold(None, {"threshold": bad}, "m.npz")


# ----------------------------------------------------------------------------- LRMMSettings and the presets
def test_the_presets_are_named_and_pinned():
    assert set(LRMM_PRESETS) == {"lrmm", "lrmm-paper", "core"} and LRMMSettings.PRESETS is LRMM_PRESETS
    assert LRMMSettings.preset("lrmm") == LRMMSettings(threshold=None, strategies=None, inputs=None)
    assert LRMMSettings.preset("lrmm-paper") == LRMMSettings(threshold=0.85, strategies=(BrakeTurn(),))
    assert LRMMSettings.preset("core") == LRMMSettings(strategies=())
    assert LRMMSettings.preset("lrmm-paper", threshold=0.5) == LRMMSettings(threshold=0.5, strategies=(BrakeTurn(),))


def test_an_unknown_preset_is_refused_listing_the_presets():
    with pytest.raises(ValueError) as e:
        LRMMSettings.preset("fast")
    assert str(e.value) == "unknown LRMMSettings preset 'fast'; the presets are: ['core', 'lrmm', 'lrmm-paper']"
    from rmm_guardians.lrmm.guardian import LRMMGuardian

    with pytest.raises(ValueError, match=r"unknown LRMMSettings preset 'fast'; the presets are: \['core', 'lrmm'"):
        LRMMGuardian(settings="fast")


def test_settings_parse_and_check_their_strategies_when_made():
    assert LRMMSettings(strategies="SafestCandidate, Commit(steps=18)").strategies == (SafestCandidate(), Commit(18))
    assert LRMMSettings(strategies=[Commit(steps=2)]).strategies == (Commit(steps=2),)
    assert LRMMSettings(strategies="").strategies == () == LRMMSettings(strategies=[]).strategies
    # edits of the stored composition are kept as written (checked now, applied once the model is known)
    assert LRMMSettings(strategies="-Commit, +Restart(speed=0.5)").strategies == ("-Commit", "+Restart(speed=0.5)")
    with pytest.raises(ValueError, match="unknown strategy 'Nope'"):
        LRMMSettings(strategies="-Nope")
    with pytest.raises(ValueError, match="either every item edits the stored ones"):
        LRMMSettings(strategies="-Commit, Restart")
    with pytest.raises(ValueError, match="strategies must be a spec string, a sequence of Strategy objects or None"):
        LRMMSettings(strategies=Commit(steps=1))  # one object, not a sequence
    with pytest.raises(ValueError, match="inputs must be an observation field name"):
        LRMMSettings(inputs=["rays"])
    with pytest.raises(TypeError, match=r"unknown LRMMSettings setting\(s\) \['commit'\]"):
        LRMMSettings().replace(commit=3)


def test_resolve_gives_fresh_copies_of_the_stored_or_given_strategies():
    stored = (SafestCandidate(), Commit(steps=18), Restart(speed=0.3))
    out = LRMMSettings().resolve(stored)
    assert out == stored and all(a is not b for a, b in zip(out, stored, strict=True))
    assert LRMMSettings(strategies="").resolve(stored) == ()
    assert LRMMSettings(strategies="-Commit").resolve(stored) == (SafestCandidate(), Restart(speed=0.3))
    assert LRMMSettings(strategies="+Commit(steps=5)").resolve(stored) == (
        SafestCandidate(),
        Commit(steps=5),
        Restart(speed=0.3),
    )  # replaced in place
    assert set(STRATEGIES) == {
        "SafestCandidate",
        "Restart",
        "BrakeTurn",
        "RayTurn",
        "RatedDriver",
        "Slide",
        "MovingAverage",
        "Commit",
    }
