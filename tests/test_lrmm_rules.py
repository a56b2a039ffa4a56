"""The LRMM presets' construction, pinned where test_lrmm.py leaves room."""

import warnings

from rmm_guardians.lrmm.guardian import PAPER_THRESHOLD, LRMMPaperGuardian


def test_the_paper_preset_is_the_heuristic_at_085_without_any_fallback_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the shipped paper model has no head: the action is given, not a fallback
        g = LRMMPaperGuardian()
    assert (g.action, g.threshold, g.commit, PAPER_THRESHOLD) == ("heuristic", 0.85, 0, 0.85)


def test_the_paper_preset_keeps_the_heuristic_even_on_a_model_with_a_head():
    from tests.test_lrmm import head_model_by_hand

    assert LRMMPaperGuardian(head_model_by_hand(decision={"threshold": 0.5, "action": "head"})).action == "heuristic"
