"""``python -m rmm_guardians.lrmm.decision MODEL --threshold T --commit N --action A [--trigger risk|driver]
[--margin M] [--restart V] [--slide] [--still S] [--no-stay] --chosen-by TEXT``

Stores the ``lrmm`` guardian's decision defaults in a trained model file (``meta["decision"]``,
see :mod:`rmm_guardians.lrmm.model`); the weights are unchanged.  ``--chosen-by`` is required: a
stored threshold always says how it was chosen.
"""

from __future__ import annotations

import argparse
import sys

from rmm_guardians.lrmm.model import set_decision

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m rmm_guardians.lrmm.decision",
        description="Store the lrmm guardian's decision defaults in a trained model file.",
    )
    p.add_argument("model")
    p.add_argument("--threshold", type=float, required=True, help="take control while the risk is above this")
    p.add_argument("--commit", type=int, required=True, help="steps to stay in control after the risk falls back")
    p.add_argument(
        "--action", default="head", choices=["head", "heuristic"], help="avoidance action (default: %(default)s)"
    )
    p.add_argument(
        "--trigger",
        choices=["risk", "driver"],
        help="take control on the state risk or the driver's control rated (default: not stored, i.e. risk)",
    )
    p.add_argument("--margin", type=float, help="with --trigger driver: the risk the safest candidate must save")
    p.add_argument("--restart", type=float, help="speed (m/s) below which the guardian in control accelerates")
    p.add_argument(
        "--slide",
        action="store_true",
        default=None,
        help="with --trigger driver: in control, apply the nearest variant of the driver's control rated safe "
        "(rmm_guardians.lrmm.nominal.Slide)",
    )
    p.add_argument(
        "--still",
        type=float,
        help="with --trigger driver: also take control when the driver's control is "
        "rated more than this above holding still (the zero control)",
    )
    p.add_argument(
        "--no-stay",
        dest="stay",
        action="store_false",
        default=None,
        help="with --trigger driver: in control, hand back as soon as the driver's control passes the "
        "take-over test (default: stay while it is rated above the threshold)",
    )
    p.add_argument("--chosen-by", required=True, help="how these values were chosen (stored with them)")
    args = p.parse_args(argv)
    try:
        set_decision(
            args.model,
            args.threshold,
            args.commit,
            args.chosen_by,
            args.action,
            trigger=args.trigger,
            margin=args.margin,
            restart=args.restart,
            slide=args.slide,
            still=args.still,
            stay=args.stay,
        )
    except (ValueError, FileNotFoundError) as e:
        print(f"{p.prog}: error: {e}", file=sys.stderr)
        return 2
    given = (
        ("trigger", args.trigger),
        ("margin", args.margin),
        ("restart", args.restart),
        ("slide", args.slide),
        ("still", args.still),
        ("stay", args.stay),
    )
    extra = "".join(f", {k} {v}" for k, v in given if v is not None)
    print(f"{args.model}: decision threshold {args.threshold}, commit {args.commit}, action {args.action}{extra}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
