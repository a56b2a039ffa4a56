"""``python -m rmm_guardians.lrmm.decision MODEL --threshold T --strategies SPEC --chosen-by TEXT``

Stores the ``lrmm`` guardian's decision in a trained model file (``meta["decision"]``: the
threshold, the strategies and how they were chosen; see :mod:`rmm_guardians.lrmm.settings`);
the weights are unchanged.  ``--strategies`` is a spec such as ``"SafestCandidate,
Commit(steps=18), Restart(speed=0.3)"`` (``""``: the core alone; the names:
:data:`rmm_guardians.lrmm.strategies.STRATEGIES`).  ``--chosen-by`` is required: a stored
decision always says how it was chosen.
"""

from __future__ import annotations

import argparse
import sys

from rmm_guardians.lrmm.model import set_decision
from rmm_guardians.lrmm.strategies import STRATEGIES

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m rmm_guardians.lrmm.decision",
        description="Store the lrmm guardian's decision (threshold and strategies) in a trained model file.",
    )
    p.add_argument("model")
    p.add_argument("--threshold", type=float, required=True, help="take control while the risk is above this")
    p.add_argument(
        "--strategies",
        required=True,
        help=f"comma-separated strategies, e.g. 'SafestCandidate, Commit(steps=18)' ('': none); "
        f"built in: {', '.join(STRATEGIES)}",
    )
    p.add_argument("--chosen-by", required=True, help="how these values were chosen (stored with them)")
    args = p.parse_args(argv)
    try:
        model = set_decision(args.model, args.threshold, args.strategies, args.chosen_by)
    except (ValueError, FileNotFoundError) as e:
        print(f"{p.prog}: error: {e}", file=sys.stderr)
        return 2
    d = model.meta["decision"]
    print(f"{args.model}: decision threshold {d['threshold']}, strategies [{', '.join(d['strategies'])}]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
