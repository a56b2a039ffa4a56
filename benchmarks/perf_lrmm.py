"""The ``lrmm`` guardian's decision time on each system, optionally against another commit.

Run: ``python -m benchmarks.perf_lrmm`` (this checkout) or ``python -m benchmarks.perf_lrmm
--against REF`` (this checkout and the commit ``REF``, checked out in a temporary git worktree,
timed in alternating subprocesses, ``--rounds`` each, so both meet the same machine load).
Prints the median over rounds of each system's median decision time (wall and thread CPU, in
microseconds, over ``--steps`` decisions of the blocking env's episodes) and, with ``--against``,
the ratio this checkout / ``REF``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the blocking env of each system the lrmm guardian serves
ENVS = ("Dubins4DGuarded-v0", "Dubins3DMazeGuarded-v0", "QuadrotorRoomGuarded-v0", "CartPoleGuarded-v0")
#: import name -> folder of a checkout (pyproject.toml's package_dir)
PACKAGES = {"rmm_envs": "rmm_envs", "rmm_guardians": "guardians", "rmm_bench": "benchmarks/bench"}


def decision_medians(steps: int) -> dict[str, list[float]]:
    """``env id -> [wall median, CPU median]`` (seconds) of ``steps`` lrmm decisions on it, timed
    by :func:`benchmarks.perf_guardians.decision_times` (imported as a sibling: this runs in the
    child, the script's folder first on the path)."""
    from perf_guardians import decision_times  # type: ignore[import-not-found]

    import rmm_envs  # noqa: F401
    from rmm_guardians import make_guardian

    out = {}
    for env_id in ENVS:
        cpu: list[float] = []
        wall = decision_times(make_guardian("lrmm", env_id=env_id), env_id=env_id, steps=steps, cpu=cpu)
        out[env_id] = [statistics.median(wall), statistics.median(cpu)]
    return out


def _run(path: str | None, steps: int) -> dict[str, list[float]]:
    """One timing run in a fresh interpreter, importing the packages from ``path`` (a folder of
    links named as the packages) if given, else as installed."""
    extra = ["--path", path] if path else []
    done = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--json", "--steps", str(steps), *extra],
        cwd=tempfile.gettempdir(),
        capture_output=True,
        text=True,
        check=False,
    )
    if done.returncode != 0:
        raise SystemExit(f"perf_lrmm: a timing run failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m benchmarks.perf_lrmm", description=__doc__.splitlines()[0])
    p.add_argument("--against", metavar="REF", help="also time the commit REF (a git worktree), alternating")
    p.add_argument("--rounds", type=int, default=3, help="subprocess runs of each side (default %(default)s)")
    p.add_argument("--steps", type=int, default=3000, help="decisions per system and run (default %(default)s)")
    p.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--path", help=argparse.SUPPRESS)  # with --json: import the packages from there
    args = p.parse_args(argv)
    if args.path:
        sys.path.insert(0, args.path)
    if args.json:
        print(json.dumps(decision_medians(args.steps)))
        return 0
    sides: dict[str, list[dict]] = {"this checkout": [], args.against or "": []}
    with tempfile.TemporaryDirectory() as tmp:
        base = None
        if args.against:
            tree = Path(tmp) / "tree"
            subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), args.against], check=True)
            base = Path(tmp) / "path"
            base.mkdir()
            for name, folder in PACKAGES.items():
                (base / name).symlink_to(tree / folder)
        try:
            for r in range(args.rounds):
                order = (
                    [("this checkout", None), (args.against, str(base))] if args.against else [("this checkout", None)]
                )
                for label, path in order if r % 2 == 0 else order[::-1]:
                    sides[label or ""].append(_run(path, args.steps))
        finally:
            if args.against:
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
    print(f"lrmm decision time, median over {args.rounds} runs of each run's median ({args.steps} decisions), us")
    head = f"  {'env':28s} {'wall':>8s} {'CPU':>8s}"
    print(head + (f" {'wall ' + args.against:>16s} {'CPU':>8s} {'ratio':>6s}" if args.against else ""))
    for env_id in ENVS:
        now = [statistics.median(run[env_id][k] for run in sides["this checkout"]) * 1e6 for k in (0, 1)]
        line = f"  {env_id:28s} {now[0]:8.1f} {now[1]:8.1f}"
        if args.against:
            then = [statistics.median(run[env_id][k] for run in sides[args.against]) * 1e6 for k in (0, 1)]
            line += f" {then[0]:16.1f} {then[1]:8.1f} {now[1] / then[1]:6.2f}"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
