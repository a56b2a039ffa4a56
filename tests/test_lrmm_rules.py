"""The LRMM presets' construction, pinned where test_lrmm.py leaves room."""

import warnings

from rmm_guardians.lrmm.guardian import PAPER_THRESHOLD, LRMMPaperGuardian
from rmm_guardians.lrmm.strategies import BrakeTurn


def test_the_paper_preset_is_the_heuristic_at_085_without_any_fallback_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the shipped paper model has no head: the rule is given, not a fallback
        g = LRMMPaperGuardian()
    assert (g.strategies, g.threshold, g.threshold_source, PAPER_THRESHOLD) == ((BrakeTurn(),), 0.85, "argument", 0.85)


def test_the_paper_preset_keeps_the_heuristic_even_on_a_model_with_a_head():
    from tests.test_lrmm import head_model_by_hand

    stored = {"threshold": 0.5, "strategies": ["SafestCandidate()", "Commit(steps=4)"]}
    g = LRMMPaperGuardian(head_model_by_hand(decision=stored))
    assert (g.strategies, g.threshold) == ((BrakeTurn(),), 0.85)  # neither the stored rule nor its threshold
