"""``docs/reference-results.md``: the shipped reference results as the results page leads with them.

Run ``python -m rmm_bench.reference_page`` (from the repository root; ``--docs DIR`` for
another docs folder, ``--no-figures`` for the page alone) to regenerate the page and its
figures (``docs/figures/reference_NAME.png``).  Offers :func:`render` and :func:`write`.

Per shipped database (:func:`rmm_bench.reference.reference_dbs`), in the page's order: the
commands that made it (from its manifest), the rates figure
(:func:`rmm_bench.report_figures.plot_rates`), the summary paragraph
(:func:`rmm_bench.pairwise.summary`), Table I as ``rmm-bench report`` prints it, the guardians'
counters and the matrix of paired differences of each outcome (Holm–Bonferroni over its pairs),
every agent stored under the newest configuration, as ``rmm-bench report DIR`` shows it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rmm_bench.html_pairs import section_comparison
from rmm_bench.manifest import load_manifests
from rmm_bench.names import md_cell
from rmm_bench.pairwise import ALPHA, CORRECTION, OUTCOMES, pairwise_matrices, summary
from rmm_bench.reference import reference_dbs
from rmm_bench.report import newest_configuration, table_rows
from rmm_bench.report_figures import plot_rates
from rmm_bench.report_tables import counter_columns, counter_text, format_tables
from rmm_bench.store import ResultsStore

__all__ = ["COMMAND", "PAGE", "main", "render", "write"]

#: the command that writes the page, as its first lines say
COMMAND = "python -m rmm_bench.reference_page"
#: the page, under the docs folder
PAGE = "reference-results.md"


def _figure(name: str) -> str:
    return f"figures/reference_{name}.png"


def _commands(name: str) -> str:
    lines = [
        f"rmm-bench {' '.join(c)} --out results/{m.name}"
        for m in load_manifests()
        if m.kind == "reference" and m.reference == name
        for c in m.commands
    ]
    return "```bash\n" + "\n".join(lines) + "\n```\n\n" if lines else ""


def _cell(matrix, a: str, b: str) -> str:
    cell = matrix.get((a, b))
    if cell is None:
        return ""
    if not cell.tested:
        return "no test"
    return f"{100 * cell.diff:+.1f}" + ("*" if cell.significant else "")


def _matrices(matrices: dict, names: list[str]) -> str:
    out = []
    for outcome, matrix in matrices.items():
        m = sum(c.tested for c in matrix.values())
        out.append(f"**{OUTCOMES[outcome][0]} rate**, row − column, percentage points ({m} pairs):\n")
        out.append("| A \\ B | " + " | ".join(map(md_cell, names[1:])) + " |\n|---|" + "---|" * (len(names) - 1))
        for i, a in enumerate(names[:-1]):
            cells = [_cell(matrix, a, b) if j > i else "" for j, b in enumerate(names[1:], 1)]
            out.append(f"| **{md_cell(a)}** | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def _counters(rows: list[dict]) -> str:
    names = counter_columns(rows)
    if not names:
        return ""
    lines = ["| Agent | " + " | ".join(f"`{n}`" for n in names) + " |", "|---|" + "---|" * len(names)]
    for r in rows:
        lines.append(
            f"| {md_cell(r['agent'])} | " + " | ".join(counter_text(r["counters"].get(n)) or "—" for n in names) + " |"
        )
    return (
        "Each guardian's own `stats()`, summed over its episodes (—: it reports no such statistic; "
        "`solves`, `cache_hits` and `*_seconds` count this machine's cache and time, not results):\n\n"
        + "\n".join(lines)
        + "\n\n"
    )


def _section(db: Path, figures: Path | None) -> str:
    store = ResultsStore(db, read_only=True)
    try:
        invs = newest_configuration(store)
        run_keys: dict[str, str] = {}
        for inv in invs:
            run_keys.update(inv["run_keys"])
        rows = table_rows(store, run_keys, max(inv["episodes"] for inv in invs))
    finally:
        store.close()
    args = invs[-1]["args"]
    c, why = section_comparison(db, run_keys, resamples=1)  # the page shows no bootstrap interval
    matrices = pairwise_matrices(c.pairs) if c is not None else {}
    if figures is not None:
        plot_rates(rows, figures / Path(_figure(db.stem)).name, dpi=80)
    episodes = max(r["episodes"] for r in rows)
    return (
        f"## {args['env']} (`{db.name}`)\n\n"
        f"{len(rows)} agents, {episodes:,} episodes each, clock {args['clock']}, seed {args['seed']}; made by:\n\n"
        f"{_commands(db.stem)}"
        f"![Each agent's success, collision, avoidable-collision and timeout rate with its 95% interval]"
        f"({_figure(db.stem)})\n\n"
        f"{summary(rows, matrices)}\n\n"
        f"{format_tables(rows, measured=True)['md']}\n"
        f"{_counters(rows)}"
        + (_matrices(matrices, list(c.agents)) if c is not None else f"No paired comparison: {why}\n")
    )


def render(figures: Path | None = None, dbs: list[Path] | None = None) -> str:
    """The page's text; with ``figures`` (a folder) its figures are written there too."""
    sections = [_section(db, figures) for db in (dbs if dbs is not None else reference_dbs())]
    return (
        "# Reference results\n\n"
        f"<!-- generated by `{COMMAND}` from rmm_bench/reference/*.db; do not edit: rerun it -->\n\n"
        "The fixed-clock results shipped with the package (`rmm_bench/reference/`), as `rmm-bench report DIR "
        "--html` leads with them: each agent's rates with 95% Wilson intervals, a summary, Table I and the "
        "paired differences of every two agents on the same episodes (`rmm-bench compare`'s order and signs: "
        f"row − column). `*`: significant after {CORRECTION} over the pairs of that outcome (exact McNemar "
        f"tests, family-wise error rate {ALPHA:.0%}). Compare a run of your own with them by "
        "`rmm-bench compare DIR --reference` ([comparing guardians](comparing.md)); the doomed and avoidable "
        "starts are explained in [concepts](concepts.md).\n\n" + "\n".join(sections)
    )


def write(docs: Path, figures: bool = True) -> Path:
    """Write ``docs/reference-results.md`` (and, with ``figures``, ``docs/figures/reference_*.png``)."""
    path = docs / PAGE
    path.write_text(render(docs / "figures" if figures else None))
    return path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog=COMMAND, description="Regenerate docs/reference-results.md and its figures.")
    p.add_argument("--docs", type=Path, default=Path("docs"), help="the docs folder (default: docs)")
    p.add_argument("--no-figures", action="store_true", help="write the page only")
    args = p.parse_args(argv)
    if not args.docs.is_dir():
        print(f"{COMMAND}: error: {args.docs} is not a directory", file=sys.stderr)
        return 2
    print(f"wrote {write(args.docs, figures=not args.no_figures)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
