"""The report's figures (PNG, matplotlib): every agent's outcome rates with their 95% intervals
(:func:`plot_rates`, what the results page and ``docs/reference-results.md`` lead with), the
outcome bars and compute time against collisions (:func:`plot_outcomes`, ``outcomes.png``) and
a latency sweep (:func:`plot_latency`).

Offers :data:`RATES` and :func:`rate_intervals` too: each rate of a Table I row (as
:func:`rmm_bench.report.table_rows` returns it) with its 95% Wilson score interval over the
episodes it counts.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

from rmm_bench.metrics import wilson_interval

__all__ = ["RATES", "plot_latency", "plot_outcomes", "plot_rates", "rate_intervals", "rates_order"]

#: the rates the figure shows, in its order: row key -> (title, colour)
RATES = {
    "goal": ("Success", "tab:green"),
    "collision": ("Collision", "tab:red"),
    "avoidable_collision": ("Collision, avoidable starts", "tab:orange"),
    "timeout": ("Timeout", "tab:gray"),
}


def rate_intervals(row: dict) -> dict[str, tuple[float, float, float, int]]:
    """Rate key -> ``(rate, low, high, n)`` in % (the 95% Wilson score interval over the ``n``
    episodes it counts: those with a result, or for ``avoidable_collision`` the avoidable starts
    among them); a rate the row does not hold (starts not assessed, no episode) is left out."""
    out = {}
    for key in RATES:
        if key == "avoidable_collision":
            if "avoidable_collision" not in row:
                continue
            p, n = row["avoidable_collision"][0] / 100, int(row.get("avoidable_starts", 0))
        else:
            p, n = row.get(f"total_{key}", math.nan) / 100, int(row.get("with_result", row.get("episodes", 0)))
        if n <= 0 or math.isnan(p):
            continue
        lo, hi = wilson_interval(p, n)
        out[key] = (100 * p, 100 * lo, 100 * hi, n)
    return out


def rates_order(rows: list[dict]) -> list[int]:
    """The indices of ``rows`` sorted as the figure lists them: fewest collisions first (then the
    most successes, then the name)."""

    def key(i: int):
        rates = rate_intervals(rows[i])
        collision = rates.get("collision", (math.inf,))[0]
        return (collision, -rates.get("goal", (0.0,))[0], str(rows[i]["agent"]))

    return sorted(range(len(rows)), key=key)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _rate_panel(ax, rows: list[dict], key: str, names: bool) -> None:
    title, colour = RATES[key]
    n = len(rows)
    ax.set_ylim(n - 0.5, -0.5)  # the first row on top
    if names:
        ax.set_yticks(range(n), [str(r["agent"]) for r in rows])
    else:  # the panel shares the first one's rows: keep its names, show none
        ax.tick_params(axis="y", labelleft=False)
    for y in range(1, n, 2):  # banded rows: an agent read across the panels
        ax.axhspan(y - 0.5, y + 0.5, color="#f3f3f5", zorder=0, linewidth=0)
    ax.set_xlim(-2, 102)  # a point at 0 or 100 % whole
    ax.set_xticks(range(0, 101, 20))
    ax.grid(axis="x", color="#ddd", linewidth=0.6)
    ax.set_axisbelow(True)
    for y, r in enumerate(rows):
        rate = rate_intervals(r).get(key)
        if rate is None:
            ax.text(2, y, "not assessed", va="center", fontsize="small", color="#666")
            continue
        p, lo, hi, _ = rate
        ax.errorbar(
            p,
            y,
            xerr=[[max(0.0, p - lo)], [max(0.0, hi - p)]],
            fmt="o",
            color=colour,
            markersize=5,
            capsize=3,
            linewidth=1.5,
        )
        # the value beside its own interval, on its own row: it covers no other agent's point
        right = hi < 80
        ax.text(hi + 2 if right else lo - 2, y, f"{p:.1f}", va="center", ha="left" if right else "right",
                fontsize="small")  # fmt: skip
    ax.set_title(f"{title} [%]", fontsize="medium", loc="left")
    ax.tick_params(axis="y", length=0)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def plot_rates(rows: list[dict], target=None, keys=tuple(RATES), layout: str = "row", dpi: int = 100) -> bytes:
    """Each agent's rates (``keys``, of :data:`RATES`) as points with their 95% Wilson intervals,
    one panel per rate, agents in :func:`rates_order` on every panel: ``layout`` ``"row"`` puts
    the panels side by side, the agents named once (11 inches wide: 1,100 px at ``dpi`` 100, a
    laptop's column), ``"column"`` one above the other, each named (4.5 inches: a phone's).
    Writes the PNG to ``target`` (a path; ``None``: nowhere) and returns its bytes."""
    plt = _plt()
    keys = [k for k in keys if any(k in rate_intervals(r) for r in rows)] or ["collision"]
    ordered = [rows[i] for i in rates_order(rows)]
    height = 0.3 * len(rows) + 0.9
    if layout == "row":
        fig, axes = plt.subplots(1, len(keys), figsize=(11, height), sharey=True, squeeze=False)
    else:
        fig, axes = plt.subplots(len(keys), 1, figsize=(4.5, height * len(keys)), squeeze=False)
    for i, (ax, key) in enumerate(zip(axes.flat, keys, strict=True)):
        _rate_panel(ax, ordered, key, names=layout != "row" or i == 0)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    data = buf.getvalue()
    if target is not None:
        Path(target).write_bytes(data)
    return data


def plot_outcomes(rows: list[dict], path: Path, batch_size: int = 64, measured: bool = False) -> Path:
    """Outcome rates per agent, and collisions against compute time: the time the clock charged,
    or with ``measured`` (a fixed clock, which charges every agent the same) the guardian's
    measured decision time.  The scatter names its agents in a legend, so no name covers a point."""
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    names = [r["agent"] for r in rows]
    x = range(len(rows))
    width = 0.26
    for i, (key, colour) in enumerate([("goal", "tab:green"), ("collision", "tab:red"), ("timeout", "tab:gray")]):
        axes[0].bar(
            [j + (i - 1) * width for j in x],
            [r[key][0] for r in rows],
            width,
            yerr=[0 if math.isnan(r[key][1]) else r[key][1] for r in rows],
            color=colour,
            capsize=3,
            label=key,
        )
    # long names (``lrmm-paper``, ``cbf-paper``) run into each other when set level
    axes[0].set_xticks(list(x), names, rotation=30, ha="right")
    wilson = any(r.get("rate_spread") == "wilson95" for r in rows)
    axes[0].set_ylabel("% of episodes")
    axes[0].set_ylim(0, 118)  # headroom above 100 % so the legend covers no bar
    axes[0].legend(loc="upper center", ncols=3, fontsize="small")
    spread = f"mean ± std over batches of {batch_size}" + ("; 95% Wilson below 2 batches" if wilson else "")
    axes[0].set_title(f"Outcomes ({spread})", fontsize="medium")
    key = "decision_ms" if measured else "compute_ms"
    markers = "osD^vP*Xh<>"
    for i, r in enumerate(rows):
        x_ms = r.get(key, (float("nan"),))[0]
        if math.isnan(x_ms):
            continue
        axes[1].errorbar(
            max(x_ms, 1e-4),
            r["collision"][0],
            yerr=r["collision"][1],
            fmt=markers[i % len(markers)],
            color=f"C{i % 10}",
            capsize=3,
            label=str(r["agent"]),
        )
    axes[1].set_xscale("log")
    axes[1].margins(x=0.2)
    from matplotlib.ticker import NullFormatter

    axes[1].xaxis.set_minor_formatter(NullFormatter())  # minor labels collide on short decades
    axes[1].set_xlabel(
        "measured decision time [ms] (log)\n(the fixed clock charged every agent the same)"
        if measured
        else "policy compute time per step [ms] (log)"
    )
    axes[1].set_ylabel("collision rate [% episodes]")
    axes[1].set_title("Compute time vs collisions", fontsize="medium")
    if axes[1].has_data():
        axes[1].legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=110, bbox_inches="tight")  # the whole of every label, the legend beside
    plt.close(fig)
    return path


def plot_latency(series: dict[str, list[tuple[float, float, float]]], path: Path) -> Path:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 4))
    for agent, pts in series.items():
        pts = sorted(pts)
        ax.errorbar(
            [p[0] for p in pts], [p[1] for p in pts], yerr=[p[2] for p in pts], marker="o", capsize=3, label=agent
        )
    ax.set_xlabel("added decision latency [ms of wall time]")
    ax.set_ylabel("collision rate [% episodes]")
    ax.set_title("Compute time costs safety")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
