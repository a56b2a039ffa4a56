"""``rmm-bench tune``: choose the ``lrmm`` guardian's decision for a model on development episodes.

    rmm-bench tune --env CartPoleParallel-v0 --model mine.npz            # thresholds 0.1 ... 0.85, core alone
    rmm-bench tune --env ENV --model mine.npz --thresholds 0.2,0.3,0.5 --strategies "" \\
        --strategies "SafestCandidate, Commit(steps=18)" --max-intervention 30

Runs ``lrmm`` at every candidate (each threshold of ``--thresholds`` with each ``--strategies``
spec, the core alone by default) and the driver alone on the same ``--episodes`` episodes of
``--seed`` (default 5: development episodes; report results on another seed) under a fixed
clock, then chooses by one stated rule (:data:`RULE`): the lowest collision rate, then the
highest success rate, then the least intervention, then the higher threshold; with
``--max-intervention P`` only among candidates in control at most P% of the simulated time.
It prints the trade-off it chose from (``OUT/tune.md``, and ``OUT/tune.png``, collisions against
interventions, when matplotlib is installed) and writes the choice beside the model as
``MODEL.decision.toml`` (:mod:`rmm_guardians.lrmm.decision`), where the guardian reads it;
``--dry-run`` writes nothing there.  With ``--also-models`` every candidate also runs with models
trained the same way under other seeds, and the rule reads the mean over all of them: a decision
that holds across retraining rather than one model's luck.  Each run is kept under ``--out`` (default
``results/tune/MODEL``): the same command again resumes them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import shlex
import sys
from pathlib import Path

from rmm_bench.knob_sweep import bench_argv, read_row, run_bench
from rmm_guardians.lrmm.decision import Decision, decision_path, is_shipped, write_decision
from rmm_guardians.lrmm.guardian import LRMMGuardian
from rmm_guardians.lrmm.model import LRMMModel
from rmm_guardians.lrmm.settings import check_threshold
from rmm_guardians.lrmm.strategies import parse_strategies, strategy_specs
from rmm_guardians.lrmm.strategies.spec import spec_items

__all__ = ["DEFAULT_THRESHOLDS", "RULE", "build_parser", "choose", "cmd", "combine"]

PROG = "rmm-bench tune"
DEFAULT_THRESHOLDS = (0.1, 0.2, 0.3, 0.5, 0.7, 0.85)
#: how ``tune`` chooses, as written into the decision it writes
RULE = (
    "the lowest collision rate, then the highest success rate, then the least time in control, then the "
    "higher threshold"
)
_OWN_OPTS = ("lrmm.model", "lrmm.threshold", "lrmm.strategies", "lrmm.settings")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog=PROG,
        description="Choose the lrmm guardian's threshold (and strategies) for a model on development episodes, "
        "show the collisions-vs-interventions trade-off it chose from, and write MODEL.decision.toml beside "
        f"the model, where the guardian reads it.  The rule: {RULE}.",
    )
    p.add_argument("--env", required=True, help="the env to run (one rmm-bench runs, e.g. CartPoleParallel-v0)")
    p.add_argument("--model", required=True, type=Path, help="the model file (rmm-train's)")
    p.add_argument(
        "--thresholds",
        default=",".join(map(str, DEFAULT_THRESHOLDS)),
        help="comma-separated candidate thresholds in [0, 1] (default: %(default)s)",
    )
    p.add_argument(
        "--strategies",
        action="append",
        metavar="SPEC",
        help="candidate strategies, a spec such as 'SafestCandidate, Commit(steps=18)' (repeatable; "
        "default: '', the core alone)",
    )
    p.add_argument("--episodes", type=int, default=64, help="development episodes per candidate (default: %(default)s)")
    p.add_argument("--seed", type=int, default=5, help="their master seed; report on another (default: %(default)s)")
    p.add_argument("--clock", default="fixed:1", help="decision clock, fixed:MS (default: %(default)s)")
    p.add_argument("--workers", type=int, default=None, help="worker processes of each run (default: rmm-bench's)")
    p.add_argument(
        "--max-intervention",
        type=float,
        default=None,
        metavar="PCT",
        help="choose only among candidates in control at most PCT%% of the simulated time",
    )
    p.add_argument(
        "--agent-opt",
        action="append",
        default=[],
        metavar="lrmm.KEY=VALUE",
        help="a fixed option of every run, e.g. lrmm.inputs='\"rays\"' (repeatable)",
    )
    p.add_argument(
        "--also-models",
        default="",
        metavar="MODEL,MODEL",
        help="comma-separated models trained like --model under other seeds: every candidate runs with each, and "
        "the rule reads the mean over all of them, so the decision holds across retraining, not for one model's luck",
    )
    p.add_argument("--no-reference", action="store_true", help="do not run the driver alone for comparison")
    p.add_argument(
        "--out", type=Path, default=None, metavar="DIR", help="the directory of the runs, tune.md and tune.png"
    )
    p.add_argument("--dry-run", action="store_true", help="show the choice; write no decision beside the model")
    return p


def _thresholds(text: str) -> list[float]:
    out: list[float] = []
    for item in text.split(","):
        try:
            value = float(item)
        except ValueError:
            raise ValueError(f"--thresholds must be comma-separated numbers in [0, 1], got {item.strip()!r}") from None
        t = check_threshold(value, "--thresholds")
        if t is not None and t not in out:
            out.append(t)
    if not out:
        raise ValueError("--thresholds is empty")
    return out


def _candidates(args) -> tuple[LRMMModel, list[float], list[str]]:
    """The model, thresholds and strategy specs; a ``ValueError`` naming what is wrong."""
    if args.episodes < 1 or args.seed < 0:
        raise ValueError(f"--episodes must be >= 1 and --seed >= 0, got {args.episodes} and {args.seed}")
    if args.max_intervention is not None and not 0.0 <= args.max_intervention <= 100.0:
        raise ValueError(f"--max-intervention must be a share of time in [0, 100] %, got {args.max_intervention}")
    if not args.clock.startswith("fixed:"):
        raise ValueError(f"--clock must be fixed:MS (the same episodes for every candidate), got {args.clock!r}")
    for opt in args.agent_opt:
        if not opt.startswith("lrmm.") or opt.split("=")[0] in _OWN_OPTS:
            raise ValueError(
                f"--agent-opt {opt!r}: give lrmm.KEY=VALUE other than {', '.join(_OWN_OPTS)} (tune sets those)"
            )
    model = LRMMModel.load(args.model)
    if not args.dry_run and is_shipped(decision_path(args.model)):
        raise ValueError(
            f"{args.model} is a model this package ships, its decision part of the package: copy the model to tune "
            "a decision of your own beside the copy, or add --dry-run"
        )
    others = _also_models(args)
    thresholds = _thresholds(args.thresholds)
    specs = []
    for spec in args.strategies or [""]:
        if spec_items(spec)[1]:
            raise ValueError(f"--strategies {spec!r}: a candidate names its strategies (+/- edit a stored decision)")
        parsed = ", ".join(strategy_specs(parse_strategies(spec)))
        for m in (model, *others):  # one line if one cannot serve
            LRMMGuardian(m, env_id=args.env, threshold=thresholds[0], strategies=parsed)
        if parsed not in specs:
            specs.append(parsed)
    return model, thresholds, specs


def _also_models(args) -> list[LRMMModel]:
    """The models of ``--also-models``, loaded; a ``ValueError`` naming one given twice."""
    paths = [Path(t.strip()) for t in args.also_models.split(",") if t.strip()]
    seen = {args.model.resolve()}
    for path in paths:
        if path.resolve() in seen:
            raise ValueError(f"--also-models names {path} twice or as --model; give each model once")
        seen.add(path.resolve())
    args.also_paths = paths
    return [LRMMModel.load(path) for path in paths]


_KEYS = ("success", "collision", "timeout", "intervention")


def combine(per_model: list[dict]) -> dict:
    """One candidate's row over several models: each rate the mean of the models' means, its
    ``_std`` the sample standard deviation across those means (0 for one model: its own
    ``_std`` is kept), and ``collision_each`` the models' collision rates in order."""
    if len(per_model) == 1:
        return {**per_model[0], "collision_each": [per_model[0]["collision_mean"]]}
    out = dict(per_model[0])
    n = len(per_model)
    for k in _KEYS:
        means = [r[f"{k}_mean"] for r in per_model]
        mean = sum(means) / n
        out[f"{k}_mean"] = mean
        out[f"{k}_std"] = (sum((m - mean) ** 2 for m in means) / (n - 1)) ** 0.5
    out["collision_each"] = [r["collision_mean"] for r in per_model]
    return out


def choose(rows: list[dict], max_intervention: float | None = None) -> dict | None:
    """The row :data:`RULE` chooses among ``rows`` (each with ``threshold``, ``collision_mean``,
    ``success_mean``, ``intervention_mean``; the order given breaks the last ties), or ``None``
    when no row intervenes at most ``max_intervention`` %."""
    ok = [r for r in rows if max_intervention is None or r["intervention_mean"] <= max_intervention]
    if not ok:
        return None
    return min(ok, key=lambda r: (r["collision_mean"], -r["success_mean"], r["intervention_mean"], -r["threshold"]))


def _cell(r: dict, key: str) -> str:
    return f"{r[f'{key}_mean']:.1f} ± {r[f'{key}_std']:.1f}"


def _table(rows: list[dict], chosen: dict | None, reference: dict | None, models: int = 1) -> list[str]:
    each = models > 1
    out = [
        "| threshold | strategies | Success [%] | Collision [%] | Timeout [%] | Intervention [% sim time] |"
        + (" Collision per model [%] |" if each else "")
        + " |",
        "|---|---|---|---|---|---|" + ("---|" if each else "") + "---|",
    ]
    for r in [*rows, *([reference] if reference else [])]:
        name = "driver alone (inactive)" if r is reference else f"{r['threshold']:g}"
        specs = "" if r is reference else f"`{r['strategies']}`" if r["strategies"] else "(core alone)"
        cells = " | ".join(_cell(r, k) for k in _KEYS)
        if each:
            cells += " | " + ("" if r is reference else " / ".join(f"{c:.1f}" for c in r["collision_each"]))
        out.append(f"| {name} | {specs} | {cells} | {'chosen' if r is chosen else ''} |")
    return out


def _figure(rows: list[dict], chosen: dict | None, reference: dict | None, title: str, path: Path) -> None:
    import matplotlib  # optional: an ImportError skips the figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 4.0), dpi=120)
    for spec in dict.fromkeys(r["strategies"] for r in rows):
        line = [r for r in rows if r["strategies"] == spec]
        xs, ys = [r["intervention_mean"] for r in line], [r["collision_mean"] for r in line]
        ax.plot(xs, ys, "-o", ms=4, lw=1, label=spec or "core alone")
        for r in line:
            ax.annotate(f"{r['threshold']:g}", (r["intervention_mean"], r["collision_mean"]), fontsize=7,
                        textcoords="offset points", xytext=(4, 4))  # fmt: skip
    if chosen is not None:
        ax.plot([chosen["intervention_mean"]], [chosen["collision_mean"]], "*", color="tab:red", ms=14, label="chosen")
    if reference is not None:
        ax.plot(
            [reference["intervention_mean"]], [reference["collision_mean"]], "s", color="grey", label="driver alone"
        )
    ax.set_xlim(left=-1)
    ax.set_ylim(bottom=0)
    ax.set_xlabel("intervention [% sim time]")
    ax.set_ylabel("collision rate [% episodes]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def _bad(message: str) -> int:
    print(f"{PROG}: error: {message}", file=sys.stderr)
    return 2


def cmd(argv: list[str]) -> int:
    """``rmm-bench tune ARGS``: 0 when a decision was chosen, 2 on bad input (one line), 1 when no
    candidate meets ``--max-intervention`` (nothing written), else the status of a run that failed."""
    args = build_parser().parse_args(argv)
    try:
        model, thresholds, specs = _candidates(args)
    except (ValueError, FileNotFoundError) as e:
        return _bad(str(e))
    out = args.out or Path("results") / "tune" / args.model.stem
    models = [args.model, *args.also_paths]
    rows: list[dict] = []
    for i, spec in enumerate(specs):
        for t in thresholds:
            per_model = []
            for j, path in enumerate(models):
                folder = out / (f"s{i}_t{t:g}" + (f"_m{j}" if j else ""))
                opts = ["lrmm.model=" + json.dumps(str(path.resolve())), *args.agent_opt]
                opts += [f"lrmm.threshold={t!r}", f"lrmm.strategies={json.dumps(spec)}"]
                rc = run_bench(
                    bench_argv("lrmm", opts, folder, args.episodes, args.seed, args.clock, args.workers, args.env)
                )
                if rc:  # rmm-bench said why, in one line
                    return rc
                per_model.append(read_row(folder, "lrmm"))
            rows.append({**combine(per_model), "threshold": t, "strategies": spec})
    reference = None
    if not args.no_reference:
        argv_ref = bench_argv(
            "inactive", [], out / "inactive", args.episodes, args.seed, args.clock, args.workers, args.env
        )
        if rc := run_bench(argv_ref):
            return rc
        reference = read_row(out / "inactive", "inactive")
    chosen = choose(rows, args.max_intervention)
    cap = "" if args.max_intervention is None else f", among candidates in control at most {args.max_intervention:g}%"
    lines = [
        f"lrmm decision for {args.model} on {args.env}: {args.episodes} episodes of seed {args.seed}, clock {args.clock}",
        "",
        *_table(rows, chosen, reference, len(models)),
        "",
        f"Rule: {RULE}{cap}."
        + (
            f" Each rate is the mean over {len(models)} models ({', '.join(p.name for p in models)}) ± the standard "
            "deviation across them."
            if len(models) > 1
            else ""
        ),
    ]
    out.mkdir(parents=True, exist_ok=True)
    (out / "tune.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    try:
        _figure(rows, chosen, reference, f"lrmm on {args.env}: {args.model.name}", out / "tune.png")
        print(f"The trade-off: {out / 'tune.md'} and {out / 'tune.png'}")
    except ImportError:
        print(f"The trade-off: {out / 'tune.md'} (no figure: matplotlib is not installed)")
    if chosen is None:
        least = min(rows, key=lambda r: r["intervention_mean"])
        print(
            f"{PROG}: no candidate is in control at most {args.max_intervention:g}% of the time (the least: "
            f"{least['intervention_mean']:.1f}% at threshold {least['threshold']:g}); nothing written: raise "
            "--max-intervention or try higher --thresholds",
            file=sys.stderr,
        )
        return 1
    if reference is not None and chosen["collision_mean"] >= reference["collision_mean"]:
        print(
            f"note: the chosen decision collides as often as the driver alone ({chosen['collision_mean']:.1f}% "
            f"against {reference['collision_mean']:.1f}%): the model may not see what makes this env fail"
        )
    how = (
        f"rmm-bench tune's rule: {RULE}{cap}; over thresholds {', '.join(f'{t:g}' for t in thresholds)} x "
        f"strategies {' | '.join(repr(s) for s in specs)}: success {chosen['success_mean']:.1f}%, collision "
        f"{chosen['collision_mean']:.1f}%, timeout {chosen['timeout_mean']:.1f}%, in control "
        f"{chosen['intervention_mean']:.1f}% of the time"
        + (
            ""
            if len(models) == 1
            else f", each the mean over {len(models)} models ({', '.join(p.name for p in models)}), collisions "
            + " / ".join(f"{c:.1f}" for c in chosen["collision_each"])
            + "%"
        )
        + ("" if reference is None else f" (the driver alone: collision {reference['collision_mean']:.1f}%)")
    )
    decision = Decision(
        chosen["threshold"],
        chosen["strategies"],
        {
            "how": how,
            "command": f"{PROG} {shlex.join(argv)}",
            "seeds": f"rmm-bench --seed {args.seed}, {args.episodes} episodes of {args.env}, clock {args.clock}",
            "date": datetime.date.today().isoformat(),
        },
        model.file_sha256,
    )
    spec = chosen["strategies"] or "the core alone"
    print(f"Chosen: threshold {chosen['threshold']:g}, strategies {spec}")
    if args.dry_run:
        print(f"--dry-run: nothing written beside {args.model}")
        return 0
    path = decision_path(args.model)
    existed = path.exists()
    write_decision(path, decision, args.model.name)
    print(f"{'replaced' if existed else 'wrote'} {path}: the lrmm guardian reads it with {args.model}")
    return 0


if __name__ == "__main__":
    sys.exit(cmd(sys.argv[1:]))
