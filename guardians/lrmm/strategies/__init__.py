"""The ``lrmm`` guardian's strategies: named rules composed around its core.

The core (:class:`rmm_guardians.lrmm.guardian.LRMMGuardian`) takes control while the model's risk
of the observation is above the threshold and applies the env's safe default.  A strategy changes
*when* it is in control (:meth:`Strategy.take`) or *what* it applies (:meth:`Strategy.act`);
strategies run in the order given, each seeing the verdict or action of those before it.
Built in (:data:`STRATEGIES`): :class:`SafestCandidate`, :class:`BrakeTurn`, :class:`RayTurn`,
:class:`Restart`, :class:`Slide` (what), :class:`RatedDriver`, :class:`MovingAverage`,
:class:`Commit` (when).  A strategy of one's own subclasses :class:`Strategy`; it is given as an
object in Python, or as ``module:Class(args)`` in a spec (:func:`parse_strategies`, e.g.
``"SafestCandidate, Commit(steps=18)"``; items starting with ``-``/``+`` edit the stored
composition).  Why each built-in exists and what it adds: docs/decisions/0024-lrmm-core-and-strategies.md.
"""

from rmm_guardians.lrmm.strategies.base import DecisionContext, Strategy
from rmm_guardians.lrmm.strategies.candidates import Restart, SafestCandidate
from rmm_guardians.lrmm.strategies.driver import SLIDE_MOVES, SLIDE_TURNS, RatedDriver, Slide
from rmm_guardians.lrmm.strategies.rays import BrakeTurn, RayTurn
from rmm_guardians.lrmm.strategies.spec import STRATEGIES, parse_strategies, strategy_specs
from rmm_guardians.lrmm.strategies.timing import Commit, MovingAverage

__all__ = [
    "SLIDE_MOVES",
    "SLIDE_TURNS",
    "STRATEGIES",
    "BrakeTurn",
    "Commit",
    "MovingAverage",
    "RatedDriver",
    "RayTurn",
    "Restart",
    "SafestCandidate",
    "Slide",
    "DecisionContext",
    "Strategy",
    "parse_strategies",
    "strategy_specs",
]
