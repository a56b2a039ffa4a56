"""rmm_guardians.lrmm.settings: the lrmm guardian's settings and presets, and one precedence for its
threshold and strategies (argument > the decision file beside the model; ``lrmm`` refuses a model
without one unless given a threshold, ``lrmm-paper`` reads none: the paper's 0.85).  The decision
file itself: tests/test_lrmm_decision.py."""

from __future__ import annotations

import math

import pytest

from rmm_guardians.lrmm.decision import Decision, decision_path, read_decision
from rmm_guardians.lrmm.settings import LRMM_PRESETS, LRMMSettings, check_threshold
from rmm_guardians.lrmm.strategies import STRATEGIES, BrakeTurn, Commit, Restart, SafestCandidate

HOW = {"how": "a test"}


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
        Decision(bad, "", HOW)
    with pytest.raises(ValueError) as e:
        LRMMSettings(threshold=bad)
    assert str(e.value) == message


def test_the_guardian_reports_where_its_threshold_came_from():
    from rmm_guardians.lrmm.guardian import LRMMGuardian, LRMMPaperGuardian
    from rmm_guardians.lrmm.model import load_model

    g = LRMMGuardian()
    stored = read_decision(decision_path(g.model.path))
    assert (g.threshold, g.threshold_source) == (stored.threshold, "stored decision")
    assert LRMMGuardian(threshold=0.5).threshold_source == "argument"
    assert (LRMMPaperGuardian().threshold, LRMMPaperGuardian().threshold_source) == (0.85, "argument")
    bare = load_model(g.model.path)
    del bare.path  # a model object without a file: no decision beside it
    bare.meta.pop("decision", None)
    with pytest.raises(ValueError, match=r"^lrmm: the model \(an LRMMModel without a file\) has no decision: give a"):
        LRMMGuardian(model=bare)
    h = LRMMGuardian(model=bare, threshold=0.5)
    assert (h.threshold, h.threshold_source, h.strategies) == (0.5, "argument", ())  # and the core alone
    p = LRMMPaperGuardian(model=bare, settings="core")  # lrmm-paper reads no decision: the paper's threshold
    assert (p.threshold, p.threshold_source, p.strategies) == (0.85, "paper", ())


def test_the_ends_of_the_threshold_range_are_values():
    for t in (0, 0.0, 1, 1.0):
        assert check_threshold(t) == float(t)
        assert Decision(t, "", HOW).threshold == float(t)
    for bad in (1.0000001, -1e-9):
        with pytest.raises(ValueError, match="threshold must be in"):
            Decision(bad, "", HOW)


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
