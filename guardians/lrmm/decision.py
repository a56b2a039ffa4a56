"""The ``lrmm`` guardian's decision: the text file beside the model, its one source.

A model ``NAME.npz`` has its decision (threshold, strategies, how they were chosen) in
``NAME.decision.toml`` beside it (:func:`decision_path`; the format: :func:`to_toml`); the guardian
reads nothing else.  ``rmm-bench tune`` chooses one on development episodes and writes it; by
hand: ``python -m rmm_guardians.lrmm.decision MODEL --threshold T --strategies SPEC --chosen-by
TEXT`` (``--from-model``: write out a decision an older version stored inside the model file).
Why: docs/decisions/0027-decision-files.md.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import tomllib

from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.settings import check_threshold
from rmm_guardians.lrmm.shipped import models_dir
from rmm_guardians.lrmm.strategies import STRATEGIES, Strategy, parse_strategies, strategy_specs
from rmm_guardians.lrmm.strategies.spec import spec_items

__all__ = [
    "FORMAT",
    "SUFFIX",
    "Decision",
    "decision_for",
    "decision_path",
    "is_shipped",
    "main",
    "no_decision_message",
    "read_decision",
    "set_decision",
    "to_toml",
    "write_decision",
]

FORMAT, VERSION = "rmm-lrmm-decision", 1
SUFFIX = ".decision.toml"
#: the keys of ``[chosen_by]``: ``how`` is required
CHOSEN_BY_KEYS = ("how", "command", "seeds", "date")
_TOP_KEYS = ("format", "version", "model_sha256", "threshold", "strategies", "chosen_by")
TUNE = "rmm-bench tune --env {env} --model {model}"


@dataclass(frozen=True)
class Decision:
    """A decision, checked at construction: ``threshold`` in [0, 1], ``strategies`` a spec string
    (``""``: none), ``chosen_by`` ``{"how", "command", "seeds", "date"}`` (strings, ``how``
    required), ``model_sha256`` the model bytes it was chosen for (``None``: not stated)."""

    threshold: float
    strategies: str = ""
    chosen_by: dict = field(default_factory=dict)
    model_sha256: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "threshold", check_threshold(self.threshold))
        if self.threshold is None:
            raise ValueError("threshold must be a number in [0, 1], got None")
        if not isinstance(self.strategies, str):
            raise ValueError(f"strategies must be a spec string ('': none), got {self.strategies!r}")
        if spec_items(self.strategies)[1]:
            raise ValueError(f"strategies {self.strategies!r}: a decision names its strategies; +/- edit a stored one")
        self.parsed()  # a bad name or argument is refused here, naming it
        if not isinstance(self.chosen_by, dict):
            raise ValueError(f"chosen_by must be a table of {', '.join(CHOSEN_BY_KEYS)}, got {self.chosen_by!r}")
        unknown = sorted(set(self.chosen_by) - set(CHOSEN_BY_KEYS))
        if unknown:
            raise ValueError(f"chosen_by has unknown key(s) {unknown}; it holds {', '.join(CHOSEN_BY_KEYS)}")
        for k, v in self.chosen_by.items():
            if not isinstance(v, str):
                raise ValueError(f"chosen_by.{k} must be a string, got {v!r}")
        if not str(self.chosen_by.get("how", "")).strip():
            raise ValueError("chosen_by.how must say how the threshold and strategies were chosen")
        sha = self.model_sha256
        if sha is not None and not (isinstance(sha, str) and len(sha) == 64 and set(sha) <= set("0123456789abcdef")):
            raise ValueError(f"model_sha256 must be 64 lowercase hex digits, got {sha!r}")

    def parsed(self) -> tuple[Strategy, ...]:
        """The strategies, fresh objects."""
        return parse_strategies(self.strategies)


def decision_path(model_path) -> Path:
    """Where the decision of the model file ``model_path`` lives: ``NAME.decision.toml`` beside ``NAME.npz``."""
    p = Path(model_path)
    return p.with_name(p.stem + SUFFIX)


def is_shipped(path) -> bool:
    """Whether ``path`` is one of this package's own files (beside a shipped model)."""
    try:
        return Path(path).resolve().parent == models_dir().resolve()
    except OSError:
        return False


# ---------------------------------------------------------------- the file


def _string(text: str, key: str, width: int = 100) -> str:
    """``key = "text"`` as a TOML basic string; a long one wrapped with line-ending backslashes,
    which a reader joins back (each break follows a space and precedes a non-space)."""
    esc = json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")
    if len(esc) <= width:
        return f"{key} = {esc}"
    body, lines, start = esc[1:-1], [], 0
    while len(body) - start > width:
        cut = body.rfind(" ", start, start + width)
        while cut > start and body[cut + 1 : cut + 2].isspace():
            cut = body.rfind(" ", start, cut)
        if cut <= start:
            break
        lines.append(body[start : cut + 1] + "\\")
        start = cut + 1
    lines.append(body[start:] + '"""')
    return f'{key} = """\\\n' + "\n".join(lines)


def _number(x: float) -> str:
    if not math.isfinite(x):
        raise ValueError(f"a decision holds finite numbers, got {x}")
    return repr(float(x))


def to_toml(decision: Decision, model_name: str = "the model") -> str:
    """The text of ``decision``'s file (:func:`read_decision` reads it back equal)::

        format = "rmm-lrmm-decision"
        version = 1
        model_sha256 = "6f1c..."   # the model bytes it was chosen for (optional; others are refused)
        threshold = 0.25           # in control while the risk is above it, in [0, 1]
        strategies = "SafestCandidate(), Commit(steps=18)"   # a spec ("": the core alone)

        [chosen_by]                # how: required; command, seeds, date: optional
        how = "the lowest collision rate, then ..."
        command = "rmm-bench tune --env ... --model ..."
        seeds = "rmm-bench --seed 5, 64 episodes"
        date = "2026-12-05"

    A long string is wrapped with TOML's line-ending backslashes, which a reader joins back."""
    out = [
        f"# The lrmm guardian's decision for {model_name}, the model file beside this one: its one source,",
        "# read by rmm_guardians.lrmm.decision.  Choose another: rmm-bench tune (docs/getting-started.md).",
        f'format = "{FORMAT}"',
        f"version = {VERSION}",
    ]
    if decision.model_sha256:
        out.append(f'model_sha256 = "{decision.model_sha256}"')
    out += [f"threshold = {_number(decision.threshold)}", _string(decision.strategies, "strategies"), "", "[chosen_by]"]
    out += [_string(decision.chosen_by[k], k) for k in CHOSEN_BY_KEYS if k in decision.chosen_by]
    return "\n".join(out) + "\n"


def read_decision(path) -> Decision:
    """The decision in the file ``path``; a ``ValueError`` naming the file and what is wrong."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: not a readable decision file ({e})") from None
    if data.get("format") != FORMAT or data.get("version") != VERSION:
        raise ValueError(
            f"{path}: expected format {FORMAT!r} version {VERSION}, got {data.get('format')!r} "
            f"version {data.get('version')!r}"
        )
    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown or "threshold" not in data:
        what = f"unknown key(s) {unknown}" if unknown else "no threshold"
        raise ValueError(f"{path}: {what}; a decision file holds {', '.join(_TOP_KEYS)}")
    threshold = data["threshold"]
    if isinstance(threshold, bool) or not isinstance(threshold, (int, float)):
        raise ValueError(f"{path}: threshold must be a number in [0, 1], got {threshold!r}")
    try:
        return Decision(
            float(threshold), data.get("strategies", ""), data.get("chosen_by", {}), data.get("model_sha256")
        )
    except ValueError as e:
        raise ValueError(f"{path}: {e}") from None


def write_decision(path, decision: Decision, model_name: str | None = None) -> Path:
    """Write ``decision`` to ``path`` atomically (a temporary file, then a rename)."""
    path = Path(path)
    text = to_toml(decision, model_name or path.name.removesuffix(SUFFIX) + ".npz")
    if read_decision_text(text) != decision:  # never write what does not read back the same
        raise ValueError(f"{path}: the decision does not survive its own file format")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)
    return path


def read_decision_text(text: str) -> Decision:
    data = tomllib.loads(text)
    return Decision(float(data["threshold"]), data["strategies"], data["chosen_by"], data.get("model_sha256"))


# ---------------------------------------------------------------- for a model


def _where(model) -> str:
    path = getattr(model, "path", None)
    return str(path) if path is not None else "the model (an LRMMModel without a file)"


def no_decision_message(model, env_id: str) -> str:
    """The one line refusing ``model`` without a decision: the command that chooses one, or a threshold."""
    path = getattr(model, "path", None)
    where = _where(model)
    beside = f" (no {decision_path(path).name} beside it)" if path is not None else ""
    tune = f"choose one on development episodes with `{TUNE.format(env=env_id, model=path)}`, or " if path else ""
    return (
        f"lrmm: {where} has no decision{beside}: {tune}give a threshold "
        "(--agent-opt lrmm.threshold=0.5; in Python threshold=0.5)"
    )


def decision_for(model: LRMMModel, env_id: str) -> tuple[Decision | None, Path | None, str | None]:
    """The decision of ``model`` (read from beside its file), that file and the SHA-256 of its
    bytes; ``(None, None, None)`` without one.  A ``ValueError`` for a bad file, a file chosen for
    other model bytes, or a decision an older version stored inside the model file."""
    path = getattr(model, "path", None)
    file = decision_path(path) if path is not None else None
    if file is None or not file.is_file():
        if model.meta.get("decision"):  # written by an older version: named, never read
            fix = (
                f"write it beside it as {file.name} with `python -m rmm_guardians.lrmm.decision {path} --from-model`"
                if file is not None
                else "give threshold= and strategies=, or save the model and write it beside the file"
            )
            raise ValueError(
                f"lrmm: {_where(model)} holds a decision inside the model file (meta), which is no longer read: "
                f"{fix}, or choose one: `{TUNE.format(env=env_id, model=path or 'FILE')}`"
            )
        return None, None, None
    data = file.read_bytes()
    decision = read_decision(file)
    sha = getattr(model, "file_sha256", None)
    if decision.model_sha256 and sha and decision.model_sha256 != sha:
        raise ValueError(
            f"lrmm: {file} was chosen for other model bytes (SHA-256 {decision.model_sha256[:12]}..., {path} is "
            f"{sha[:12]}...): choose again with `{TUNE.format(env=env_id, model=path)}`"
        )
    return decision, file, hashlib.sha256(data).hexdigest()


def set_decision(path, threshold: float, strategies, chosen_by, model_sha256: bool = True) -> Decision:
    """Write the decision of the model file ``path`` beside it (the model is not touched):
    ``threshold``, ``strategies`` (a spec string or a sequence of strategies; ``""``: none; items
    starting with ``+``/``-`` edit the decision there already) and ``chosen_by`` (the ``how``
    text, or a ``[chosen_by]`` dict); a ``ValueError`` naming a bad value or a strategy the
    model cannot serve."""
    chosen = {"how": chosen_by.strip()} if isinstance(chosen_by, str) else dict(chosen_by)
    model = LRMMModel.load(path)
    file = decision_path(path)
    stored = read_decision(file).parsed() if file.is_file() else ()
    parsed = parse_strategies(strategies, stored)
    for s in parsed:
        s.check_model(model, None)
    decision = Decision(
        threshold, ", ".join(strategy_specs(parsed)), chosen, model.file_sha256 if model_sha256 else None
    )
    write_decision(file, decision, Path(path).name)
    return decision


def _from_model(path) -> Decision:
    """The decision an older version stored in the model file's ``meta["decision"]``, written beside it."""
    model = LRMMModel.load(path)
    old = model.meta.get("decision")
    if not isinstance(old, dict) or "threshold" not in old:
        raise ValueError(f"{path} stores no decision inside it (meta['decision'])")
    specs = old.get("strategies", [])
    if not isinstance(specs, list) or not all(isinstance(s, str) for s in specs):
        raise ValueError(f"{path}: its stored strategies must be a list of spec strings, got {specs!r}")
    how = str(old.get("chosen_by") or "stored inside the model file by an older version")
    return set_decision(path, old["threshold"], ", ".join(specs), how)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m rmm_guardians.lrmm.decision",
        description="Write the lrmm guardian's decision (threshold and strategies) beside a trained model file, "
        "as MODEL.decision.toml (rmm-bench tune chooses one on development episodes).",
    )
    p.add_argument("model")
    p.add_argument("--threshold", type=float, help="take control while the risk is above this")
    p.add_argument(
        "--strategies",
        help=f"comma-separated strategies, e.g. 'SafestCandidate, Commit(steps=18)' ('': none); "
        f"built in: {', '.join(STRATEGIES)}",
    )
    p.add_argument("--chosen-by", help="how these values were chosen (stored with them)")
    p.add_argument("--from-model", action="store_true", help="write out the decision stored inside the model file")
    args = p.parse_args(argv)
    given = [a for a in ("threshold", "strategies", "chosen_by") if getattr(args, a) is not None]
    try:
        if args.from_model:
            if given:
                raise ValueError("--from-model takes no --threshold, --strategies or --chosen-by")
            d = _from_model(args.model)
        elif len(given) != 3:
            raise ValueError("give --threshold, --strategies and --chosen-by (or --from-model)")
        else:
            d = set_decision(args.model, args.threshold, args.strategies, args.chosen_by)
    except (ValueError, FileNotFoundError) as e:
        print(f"{p.prog}: error: {e}", file=sys.stderr)
        return 2
    print(f"{decision_path(args.model)}: decision threshold {d.threshold}, strategies [{d.strategies}]")
    return 0


if __name__ == "__main__":
    sys.exit(main())
