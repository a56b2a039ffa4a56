"""The paper's Table I (Allen, Xiao, Rus, ICRA 2023) as it printed it, beside a run of ours.

Offers :data:`PAPER_TABLE_I`, :data:`PAPER_LABEL`, :data:`PAPER_ENVS`, :data:`NOT_REPORTED`,
:func:`paper_agent` and :func:`format_paper_table`; ``rmm-bench report`` prints the paper's
rows under ours for a run on one of :data:`PAPER_ENVS` (:mod:`rmm_bench.report`).
"""

from __future__ import annotations

from rmm_bench.report_tables import COLUMNS
from rmm_envs.defaults import DEFAULT_ENV, DEFAULT_LABELLED_ENV

__all__ = [
    "NOT_REPORTED",
    "PAPER_ENVS",
    "PAPER_EPISODES",
    "PAPER_LABEL",
    "PAPER_TABLE_I",
    "format_paper_table",
    "paper_agent",
]

#: The envs the paper's Table I describes (it evaluated guardians on its case study only, this
#: package's default system); the report prints the paper's rows next to a run on one of them.
PAPER_ENVS = (DEFAULT_ENV, DEFAULT_LABELLED_ENV)
#: How the report labels the paper's rows, after the agent's name: the paper's own implementations
#: and model, which a run here does not reproduce exactly (our ``lrmm`` is not the paper's LRMM).
PAPER_LABEL = "paper, ICRA 2023"
#: The paper's Table I figures (2048 episodes per agent; its HJ row used single-obstacle envs), per
#: agent: ``(mean, std)``, ``std`` None where the paper printed the mean alone, or the paper's text
#: where it printed a bound or an approximation.  The paper reported no errors, QP fallbacks or
#: measured decision times: the report shows ``—`` for those.
PAPER_TABLE_I: dict[str, dict] = {
    "lrmm": {
        "obs": "local",
        "n_obst": 5,
        "compute_ms": (2.4, 5.0),
        "goal": (45.3, 7.3),
        "collision": (29.7, 5.6),
        "timeout": (25.0, 4.8),
        "intervention": (30.7, 32.5),
    },
    "cbf": {
        "obs": "global",
        "n_obst": 5,
        "compute_ms": (52.9, 41.2),
        "goal": (46.2, 5.9),
        "collision": (35.1, 5.2),
        "timeout": (18.8, 3.8),
        "intervention": (32.8, 39.4),
    },
    "random": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (1.4, 2.7),
        "goal": (27.1, 6.9),
        "collision": (68.4, 5.9),
        "timeout": (4.5, 2.9),
        "intervention": "~50",
    },
    "inactive": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (1.0, 2.3),
        "goal": (44.4, 7.4),
        "collision": (55.4, 7.3),
        "timeout": (0.1, 0.5),
        "intervention": (0.0, None),
    },
    "brakes": {
        "obs": "none",
        "n_obst": 5,
        "compute_ms": (0.3, 0.7),
        "goal": (0.6, 0.9),
        "collision": (9.0, 3.8),
        "timeout": (90.4, 3.7),
        "intervention": (100.0, None),
    },
    "hj": {
        "obs": "global",
        "n_obst": 1,
        "compute_ms": (344.0, 850.0),
        "goal": (54.0, 5.2),
        "collision": (46.0, 5.3),
        "timeout": (0.0, 0.3),
        "intervention": "<1.0",
    },
}
#: The paper's episodes per agent.
PAPER_EPISODES = 2048
#: What the paper reported nothing for.
NOT_REPORTED = "—"


def _paper_cell(v) -> str:
    """A figure of the paper's table as the paper printed it: ``mean ± std`` (one decimal), the
    mean alone (``0``, ``100``), or its text (a bound, an approximation)."""
    if isinstance(v, str):
        return v
    m, s = v
    return f"{m:g}" if s is None else f"{m:.1f} ± {s:.1f}"


def paper_agent(agent: str) -> str | None:
    """The paper's row for our ``agent`` (itself, or the ``-paper`` preset of one), else None."""
    base = agent.removesuffix("-paper")
    return base if base in PAPER_TABLE_I else None


def format_paper_table(agents) -> str:
    """The paper's Table I rows for ``agents`` (names of ours: each built-in, or its ``-paper``
    preset, maps to the paper's row of that name), in Markdown with the columns of our table.
    Each row is labelled as the paper's (:data:`PAPER_LABEL`): the paper's implementations and
    model, not ours.  ``—`` where the paper reported nothing (errors, QP fallbacks).  ``""`` when
    no agent has a paper row."""
    names = list(dict.fromkeys(a for a in map(paper_agent, agents) if a is not None))
    if not names:
        return ""
    columns = [c[1] for c in COLUMNS[:-1]] + ["Intervention rate [% steps]"]  # the paper's unit
    header = ["Agent", "Observation", "Obstacles", "Episodes"] + columns + ["Errors", "QP fallbacks"]
    md = "| " + " | ".join(header) + " |\n|" + "|".join("---" for _ in header) + "|\n"
    for a in names:
        p = PAPER_TABLE_I[a]
        cells = [f"{a} ({PAPER_LABEL})", p["obs"], str(p["n_obst"]), str(PAPER_EPISODES)]
        cells += [_paper_cell(p[k]) for k, _ in COLUMNS] + [NOT_REPORTED, NOT_REPORTED]
        md += "| " + " | ".join(cells) + " |\n"
    return md + (
        f"\nThe paper's figures as it printed them: {PAPER_EPISODES} episodes per agent, its HJ row on "
        "single-obstacle envs, its intervention rate in % of steps (ours: % of simulated time); "
        f"{NOT_REPORTED}: the paper gave no figure.\n"
    )
