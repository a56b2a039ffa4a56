"""A removal item of a strategies spec names a class: written with arguments (``-Commit(steps=5)``,
as it was added), it removes the stored Commit all the same, whatever its arguments."""

from __future__ import annotations

from rmm_guardians.lrmm.strategies import Commit, Restart, SafestCandidate, parse_strategies


def test_a_removal_with_arguments_removes_by_the_class():
    stored = (SafestCandidate(), Commit(steps=18), Restart(speed=0.3))
    assert parse_strategies("-Commit(steps=5)", stored) == (SafestCandidate(), Restart(speed=0.3))
    assert parse_strategies("-Commit ( steps = 5 ), -Restart", stored) == (SafestCandidate(),)
