"""``rmm-bench ablation``: what each of the ``lrmm`` guardian's strategies adds, one system's table.

    rmm-bench ablation --env Dubins4DParallel-v0 --episodes 2048 --seed 0 --out results/ablation

Runs, on the same episodes (``--seed``, fixed 1 ms clock): the driver alone (``inactive``); the
paper's rule (``lrmm-paper``, where the system serves it); the core alone (the learned risk
above the threshold -> the env's safe default, ``lrmm.strategies=""``); the core plus each of
the stored strategies alone; the full guardian (``lrmm`` at its defaults); the full guardian
minus each strategy (``lrmm.strategies="-Name"``).  The variants come from the composition the
guardian reads for ``--env``, so a new strategy gets its rows without editing this script.
Prints (and writes to ``--out``/``<env>_seed<S>.md``) success, collision, collision from
avoidable starts, timeout and intervention rates (mean ± std over batches of 64, as Table I), and
each row's collision rate against the full guardian's on the same episodes: the paired
difference with Newcombe's 95% interval and the exact McNemar p.  Reruns resume.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import shlex
import sqlite3
import sys
from pathlib import Path

from rmm_bench.knob_sweep import run_point
from rmm_bench.manifest import MANIFESTS, table_manifest
from rmm_bench.paired import concordance, mcnemar_exact, newcombe_paired
from rmm_envs.catalog import system_of
from rmm_envs.defaults import DEFAULT_ENV
from rmm_guardians.lrmm.guardian import LRMMGuardian

__all__ = ["build_parser", "cmd", "variants"]


def variants(env_id: str) -> list[tuple[str, str, dict]]:
    """``(label, agent, options)`` of each row for ``env_id`` (options: the agent's keyword
    arguments), in the table's order; a variant the same as an earlier one (with two strategies,
    full minus one is the core plus the other) is one row with both labels."""

    stored = LRMMGuardian(env_id=env_id).strategies
    names = [s.name for s in stored]
    rows: list[tuple[str, str, dict, tuple]] = [("driver alone (inactive)", "inactive", {}, ("inactive",))]
    if "lrmm-paper" in system_of(env_id)[0].guardians:
        rows.append(("paper's rule (lrmm-paper)", "lrmm-paper", {}, ("lrmm-paper",)))
    rows.append(("core: risk > threshold -> safe default", "lrmm", {"strategies": ""}, ()))
    rows += [(f"core + {s.name}", "lrmm", {"strategies": s.spec()}, (s.name,)) for s in stored]
    rows.append((f"full guardian (lrmm): {', '.join(names) or 'no strategies'}", "lrmm", {}, tuple(names)))
    rows += [(f"full - {n}", "lrmm", {"strategies": f"-{n}"}, tuple(m for m in names if m != n)) for n in names]
    out: list[tuple[str, str, dict]] = []
    seen: dict[tuple, int] = {}
    for label, agent, opts, key in rows:
        if key in seen:  # the same guardian: keep the first row (the full guardian's options win)
            i = seen[key]
            first = out[i]
            keep = (first[1], {}) if agent == "lrmm" and not opts else first[1:]
            out[i] = (f"{first[0]} (= {label})", *keep)
            continue
        seen[key] = len(out)
        out.append((label, agent, opts))
    return out


def _slug(label: str, agent: str, opts: dict) -> str:
    spec = opts.get("strategies")
    return agent if spec is None else f"{agent}_{spec or 'core'}".replace(" ", "").replace("(", "_").replace(")", "")


def _collisions(out: Path) -> dict[int, bool]:
    """Episode -> collided, of the one run stored in ``out``."""
    with sqlite3.connect(f"file:{out / 'results.db'}?mode=ro", uri=True) as db:
        return {int(e): o == "collision" for e, o in db.execute("SELECT episode, outcome FROM episodes")}


def _paired(a: dict[int, bool], b: dict[int, bool]) -> list[str]:
    """The collision rate of ``a`` minus ``b`` on their common episodes: the difference with
    Newcombe's paired 95% interval, and the exact McNemar p."""

    common = sorted(set(a) & set(b))
    both, a_only, b_only, neither = concordance([a[e] for e in common], [b[e] for e in common])
    d, lo, hi = newcombe_paired(both, a_only, b_only, neither)
    return [f"{100 * d:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}]", f"{mcnemar_exact(a_only, b_only):.2g}"]


HEADER = [
    "variant",
    "Success [%]",
    "Collision [%]",
    "Collision, avoidable starts [%]",
    "Timeout [%]",
    "Intervention [% sim time]",
    "Collision vs full [pp, 95% CI]",
    "McNemar p",
]


def _cells(label: str, r: dict, vs: list[str]) -> list[str]:
    avoid = r.get("avoidable_collision_mean")
    avoid_text = "n/a" if avoid in (None, "") else f"{float(avoid):.1f} ± {float(r['avoidable_collision_std']):.1f}"
    rate = [f"{r[f'{k}_mean']:.1f} ± {r[f'{k}_std']:.1f}" for k in ("success", "collision")]
    rest = [f"{r[f'{k}_mean']:.1f} ± {r[f'{k}_std']:.1f}" for k in ("timeout", "intervention")]
    return [label, *rate, avoid_text, *rest, *vs]


def _command(env: str, agent: str, opts: dict, episodes: int, seed: int) -> str:
    words = ["rmm-bench", "--env", env, "--agent", agent]
    for k, v in opts.items():
        words += ["--agent-opt", shlex.quote(f"{agent}.{k}={json.dumps(v)}")]
    return " ".join(words + ["--episodes", str(episodes), "--seed", str(seed), "--clock", "fixed:1"])


def build_parser() -> argparse.ArgumentParser:
    """The ``rmm-bench ablation`` command line."""
    p = argparse.ArgumentParser(
        prog="rmm-bench ablation",
        description="What each of lrmm's strategies adds on one env: the driver alone, the paper's rule, the core, "
        "the core plus each strategy, the full guardian and the full guardian minus each strategy, on the same "
        "episodes under a fixed 1 ms clock, each row's collisions paired with the full guardian's.",
        allow_abbrev=False,
    )
    p.add_argument("--env", default=DEFAULT_ENV, help="the env of every run (default: %(default)s)")
    p.add_argument("--episodes", type=int, default=2048, help="episodes of every run (default: %(default)s)")
    p.add_argument(
        "--seed", type=int, default=0, help="master seed; episode i's seed derives from it (default: %(default)s)"
    )
    p.add_argument("--workers", type=int, default=None, help="worker processes of each run (default: rmm-bench's)")
    p.add_argument(
        "--out",
        default="results/ablation",
        metavar="DIR",
        help="the directory of the runs and the table (default: %(default)s)",
    )
    p.add_argument("--manifest", metavar="NAME", help="also write the table as manifest NAME (rmm_bench/manifests)")
    p.add_argument("--title", default="", help="with --manifest: the table's title (default: said from the run)")
    return p


def cmd(argv: list[str]) -> int:
    """``rmm-bench ablation ARGS``: the exit status (2: bad input, one line)."""
    args = build_parser().parse_args(argv)
    if args.episodes < 1:
        print(f"rmm-bench ablation: error: --episodes must be >= 1, got {args.episodes}", file=sys.stderr)
        return 2
    try:
        rows = variants(args.env)
    except (ValueError, KeyError) as e:
        print(f"rmm-bench ablation: error: {e}", file=sys.stderr)
        return 2
    base = Path(args.out) / f"{args.env}_seed{args.seed}"
    results = []
    for label, agent, opts in rows:
        out = base / _slug(label, agent, opts)
        extra = [f"{agent}.{k}={json.dumps(v)}" for k, v in opts.items()]
        sys.stderr.write(f"rmm-bench ablation: {label} -> {out}\n")
        row = run_point(agent, extra, out, args.episodes, args.seed, "fixed:1", args.workers, args.env)
        results.append((label, agent, opts, out, row))
    full = next(_collisions(out) for _, agent, opts, out, _ in results if agent == "lrmm" and not opts)
    table = [
        _cells(label, r, ["—", "—"] if agent == "lrmm" and not opts else _paired(_collisions(out), full))
        for label, agent, opts, out, r in results
    ]
    command = "rmm-bench ablation " + " ".join(shlex.quote(a) for a in argv)
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)] + [
        "| " + " | ".join(c) + " |" for c in table
    ]
    text = f"{args.env}, {args.episodes} episodes of seed {args.seed}, fixed 1 ms clock\n\nCommand: `{command}`\n\n"
    text += "\n".join(lines) + "\n"
    base.parent.mkdir(parents=True, exist_ok=True)
    (base.parent / f"{args.env}_seed{args.seed}.md").write_text(text)
    print(text)
    if args.manifest:
        fields = {
            "name": args.manifest,
            "title": args.title
            or f"`lrmm` ablation on `{args.env}`, {args.episodes} episodes of seed {args.seed}, fixed 1 ms clock",
            "section": "What each strategy adds: ablations",
            "commands": [command.replace(f" --manifest {args.manifest}", "").split(" --title")[0]],
            "measured": f"{datetime.date.today().isoformat()}, {os.cpu_count()} cores",
            "header": HEADER,
            "rows": table,
        }
        check = {
            "agents": [agent for _, agent, _, _, _ in results],
            "rates": {"Success [%]": "goal", "Collision [%]": "collision", "Timeout [%]": "timeout"},
            "commands": [_command(args.env, agent, opts, args.episodes, args.seed) for _, agent, opts, _, _ in results],
        }
        quick = [
            [
                "--env",
                args.env,
                "--agent",
                "lrmm",
                "--agent-opt",
                'lrmm.strategies=""',
                "--episodes",
                "4",
                "--seed",
                str(args.seed),
                "--clock",
                "fixed:1",
            ]
        ]
        path = MANIFESTS / f"{args.manifest}.toml"
        path.write_text(table_manifest(fields, check, quick))
        print(f"wrote {path}; store its quick fingerprints: rmm-bench reproduce {args.manifest} --quick --update")
    return 0


if __name__ == "__main__":
    sys.exit(cmd(sys.argv[1:]))
