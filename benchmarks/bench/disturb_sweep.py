"""``rmm-bench sweep --disturb KIND=L0,L1,...``: how each guardian degrades as one disturbance grows.

    rmm-bench sweep --agent lrmm,cbf,inactive --episodes 512 --disturb obs-noise.rays=0.1,0.3,1.0

Every agent runs the same episodes (seed, clock) undisturbed and at each level of the swept
disturbance (a ``--disturb`` item with several comma-separated levels; other ``--disturb`` items
are held at their one level throughout).  Level 0 is the undisturbed run, always included, so
each level's episodes pair with it: per agent and level the table gives the success, collision,
avoidable-collision and timeout rates, the time in control, and the paired difference in the
collision rate against the undisturbed episodes (Newcombe's interval for paired proportions and
the exact McNemar p-value, as ``compare``).  It writes ``disturbance_sweep.md``, ``.csv`` and
``.png`` (one curve per agent, with 95% Wilson intervals) in ``--out``; every run is stored in its
``results.db`` like any other, so ``replay`` and ``compare`` read them.
"""

from __future__ import annotations

import csv
import dataclasses
import sys
from pathlib import Path

from rmm_bench.config import BenchConfig
from rmm_bench.metrics import aggregate, avoidable_collisions, wilson_interval
from rmm_bench.names import md_cell
from rmm_bench.paired import concordance, mcnemar_exact, newcombe_paired
from rmm_bench.run_command import _interrupted, _invoke, env_error_lines, guardian_error_lines
from rmm_bench.run_plan import applicable
from rmm_bench.store import ResultsStore
from rmm_envs.disturbances import Disturbance
from rmm_envs.starts import world_key

__all__ = ["Swept", "cmd_disturbance_sweep", "split_swept"]


@dataclasses.dataclass(frozen=True)
class Swept:
    """The swept disturbance: ``KIND[.COMPONENTS]`` (``head``), its levels and its shape."""

    head: str
    levels: tuple[float, ...]
    shape: str = ""

    def at(self, level: float) -> str | None:
        """The disturbance at ``level``, canonical (``None`` at 0: undisturbed)."""
        if level == 0:
            return None
        return str(Disturbance.parse(f"{self.head}={level!r}" + (f"@{self.shape}" if self.shape else "")))

    def label(self) -> str:
        return self.head + (f"@{self.shape}" if self.shape else "")


def split_swept(argv: list[str]) -> tuple[list[str], Swept | None]:
    """``argv`` without the swept ``--disturb`` item, and that item (``None`` when no item has
    several levels).  ValueError, in one line, for two swept items or a bad level."""
    rest, swept = [], None
    i = 0
    while i < len(argv):
        arg = argv[i]
        value = None
        if arg == "--disturb" and i + 1 < len(argv):
            value, step = argv[i + 1], 2
        elif arg.startswith("--disturb="):
            value, step = arg.split("=", 1)[1], 1
        if value is None or "," not in value.partition("=")[2]:
            rest.append(arg)
            i += 1
            continue
        if swept is not None:
            raise ValueError(f"--disturb {value!r}: sweep one disturbance at a time ({swept.label()} is swept already)")
        head, _, tail = value.partition("=")
        levels_text, _, shape = tail.partition("@")
        levels: list[float] = []
        for text in levels_text.split(","):
            if not text.strip():
                continue
            d = Disturbance.parse(f"{head}={text}" + (f"@{shape}" if shape else ""))  # the level checked as one
            if d.level not in levels:
                levels.append(d.level)
        swept = Swept(head.strip(), tuple(levels), shape.strip())
        i += step
    return rest, swept


def _paired_row(rows: list[dict], base: dict[int, dict]) -> tuple[float, float, float, float, int]:
    """The collision-rate difference (points) of ``rows`` against the undisturbed ``base`` on the
    episodes both have, its 95% interval and the McNemar p-value, and how many episodes paired."""
    common = sorted(e["episode"] for e in rows if e["episode"] in base and e["outcome"] != "error")
    by = {e["episode"]: e for e in rows}
    fa = [by[e]["outcome"] == "collision" for e in common]
    fb = [base[e]["outcome"] == "collision" for e in common]
    both, a_only, b_only, neither = concordance(fa, fb)
    d, lo, hi = newcombe_paired(both, a_only, b_only, neither)
    return 100 * d, 100 * lo, 100 * hi, mcnemar_exact(a_only, b_only), len(common)


def cmd_disturbance_sweep(config: BenchConfig, swept: Swept, argv) -> int:
    """Run ``config``'s agents at level 0 and at each of ``swept``'s levels; write and print the
    table; 0, or 1 when an episode failed (as ``rmm-bench sweep``)."""
    config, meta = applicable(config)  # every option, env and guardian checked before anything is written
    out = Path(config.out)
    fixed = list(config.env_kwargs.get("disturbances", []))
    levels = (0.0, *(x for x in swept.levels if x != 0))
    store = ResultsStore(out / "results.db")
    failed: list[str] = []
    table: list[dict] = []
    try:
        store.mark_stale_invocations()
        runs = {}
        for level in levels:
            extra = swept.at(level)
            dist = sorted(fixed + ([extra] if extra else []))
            kwargs = {k: v for k, v in config.env_kwargs.items() if k != "disturbances"}
            at = dataclasses.replace(config, env_kwargs=kwargs | ({"disturbances": dist} if dist else {}))
            try:
                _, msg = _invoke(store, "sweep", at, argv, meta, at.parsed | {"disturbance": f"{swept.head}={level!r}"})
            except KeyboardInterrupt:
                return _interrupted(out)
            keys = {a: r.key for a, r in at.agent_runs().items()}
            failed += [
                f"{swept.head}={level:g}: {line}"
                for line in ([msg] if msg else [])
                + env_error_lines(store, keys, at.episodes, at.env_id)
                + guardian_error_lines(store, keys, at.episodes)
            ]
            runs[level] = keys
        doomed = {
            e: s["doomed"] for e, s in store.starts(world_key(config.env_id, config.env_kwargs, config.seed)).items()
        }
        for agent in config.agents:
            base = {e["episode"]: e for e in store.episodes(runs[0.0][agent], config.episodes)}
            for level in levels:
                rows = store.episodes(runs[level][agent], config.episodes)
                agg = aggregate(rows, config.batch_size)
                avoid = avoidable_collisions(rows, doomed, config.batch_size)
                n = agg["episodes"]
                rate = agg["total_collision"]
                resulted = n - sum(
                    1 for e in rows if e["outcome"] == "error" and e.get("error_kind") not in (None, "guardian")
                )
                lo, hi = wilson_interval(rate / 100, resulted) if resulted else (float("nan"), float("nan"))
                d, dlo, dhi, p, paired = _paired_row(rows, base)
                table.append({
                    "agent": agent, "level": level, "episodes": n,
                    "success": agg["total_goal"], "collision": rate, "collision_low": 100 * lo, "collision_high": 100 * hi,
                    "avoidable_collision": avoid.get("avoidable_collision", (float("nan"),))[0],
                    "timeout": agg["total_timeout"], "intervention": agg["intervention"][0],
                    "collision_diff": d, "diff_low": dlo, "diff_high": dhi, "p_value": p, "paired": paired,
                })  # fmt: skip
    finally:
        store.close()
    md = _markdown(table, swept, config)
    out.mkdir(parents=True, exist_ok=True)
    (out / "disturbance_sweep.md").write_text(md)
    with open(out / "disturbance_sweep.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(table[0]) if table else ["agent"])
        w.writeheader()
        w.writerows(table)
    if config.figure:
        _figure(table, swept, out / "disturbance_sweep.png")
    else:  # one from an earlier sweep would not match the table
        (out / "disturbance_sweep.png").unlink(missing_ok=True)
    print(md)
    for line in failed:
        print(f"rmm-bench sweep: {line}", file=sys.stderr)
    return 1 if failed else 0


def _markdown(table: list[dict], swept: Swept, config: BenchConfig) -> str:
    fixed = config.env_kwargs.get("disturbances", [])
    head = (
        f"{config.env_id} under `{swept.label()}` at levels {', '.join(f'{x:g}' for x in swept.levels)} "
        f"(0: undisturbed), {config.episodes} episodes of seed {config.seed}, clock {config.clock}"
        + (f", with `{'; '.join(fixed)}` throughout" if fixed else "")
        + "\n\nRates in % of episodes (intervention: % of sim time); collision change: the paired difference "
        "against the same agent's undisturbed episodes, points, 95% Newcombe interval, exact McNemar p.\n\n"
    )
    lines = [
        "| agent | level | success | collision [95%] | avoidable collision | timeout | intervention "
        "| collision change [95%] | p |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in table:
        change = "" if r["level"] == 0 else f"{r['collision_diff']:+.1f} [{r['diff_low']:+.1f}, {r['diff_high']:+.1f}]"
        p = "" if r["level"] == 0 else f"{r['p_value']:.2g}"
        lines.append(
            f"| {md_cell(r['agent'])} | {r['level']:g} | {r['success']:.1f} | {r['collision']:.1f} "
            f"[{r['collision_low']:.1f}, {r['collision_high']:.1f}] | {r['avoidable_collision']:.1f} | "
            f"{r['timeout']:.1f} | {r['intervention']:.1f} | {change} | {p} |"
        )
    return head + "\n".join(lines) + "\n"


def _figure(table: list[dict], swept: Swept, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for agent in dict.fromkeys(r["agent"] for r in table):
        pts = [r for r in table if r["agent"] == agent]
        x = [r["level"] for r in pts]
        y = [r["collision"] for r in pts]
        err = [[r["collision"] - r["collision_low"] for r in pts], [r["collision_high"] - r["collision"] for r in pts]]
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=agent)
    ax.set_xlabel(f"{swept.label()} level")
    ax.set_ylabel("collision rate [% episodes, 95% Wilson]")
    ax.set_title("Who degrades least")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
