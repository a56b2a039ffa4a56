"""rmm_guardians.lrmm.defaults: the lrmm threshold's one precedence (argument > the model file's
stored decision > the shipped entry's > the paper's 0.85)."""

from __future__ import annotations

import math

import pytest

from rmm_guardians.lrmm.defaults import PAPER_THRESHOLD, check_threshold, decision_threshold, stored_decision
from rmm_guardians.lrmm.shipped import Shipped

SHIP = Shipped({"act": "x.npz"}, decision={"threshold": 0.6, "commit": 3, "chosen_by": "a test"})


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


def test_the_stored_decision_is_the_model_files_else_the_shipped_entrys_for_its_own_model():
    own = {"threshold": 0.2, "commit": 1}
    assert stored_decision({"decision": own}, SHIP, model_given=False) is own  # the file wins over the table
    assert stored_decision({}, SHIP, model_given=False) is SHIP.decision
    assert stored_decision({}, SHIP, model_given=True) is None  # a model given by path: no shipped decision
    assert stored_decision({"decision": own}, None, model_given=True) is own
    assert stored_decision({}, None, model_given=False) is None


def test_the_threshold_precedence():
    assert decision_threshold(0.4, {"threshold": 0.6}, "m.npz") == (0.4, "argument")
    assert decision_threshold(0, {"threshold": 0.6}, "m.npz") == (0.0, "argument")  # 0 is a value, not "not given"
    assert decision_threshold(None, {"threshold": 0.6}, "m.npz") == (0.6, "stored decision")
    assert decision_threshold(None, {"commit": 2}, "m.npz") == (PAPER_THRESHOLD, "paper") == (0.85, "paper")
    assert decision_threshold(None, None, "m.npz") == (0.85, "paper")
    with pytest.raises(ValueError, match=r"^m.npz: stored decision threshold must be in \[0, 1\], got 1.2$"):
        decision_threshold(None, {"threshold": 1.2}, "m.npz")


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
    assert (h.threshold, h.threshold_source) == (0.85, "paper")


def test_the_ends_of_the_threshold_range_are_values():
    for t in (0, 0.0, 1, 1.0):
        assert check_threshold(t) == float(t)
        assert decision_threshold(None, {"threshold": t}, "m.npz") == (float(t), "stored decision")
    for bad in (1.0000001, -1e-9):
        with pytest.raises(ValueError, match="stored decision threshold must be in"):
            decision_threshold(None, {"threshold": bad}, "m.npz")
