"""Table I aggregation (docs/original-code.md, item 22), over the episodes in order.

* policy compute time, ms: per episode ``compute_time / steps``; mean and population std
  across the episodes without an error;
* success / collision / timeout rate, %: over every episode with a result, **an episode that
  ended in a guardian error included, as a failure** (neither a goal, a collision nor a
  timeout: a guardian that fails exactly when it would intervene must not look perfect, so the
  three rates add up to 100% minus the share of guardian errors, which the Errors column
  counts); episodes without a result (over the time limit, lost with their worker: kinds in
  :data:`rmm_bench.store.RETRIED_ERRORS`) are left out, and the report marks the run
  incomplete.  Episodes are split in order into consecutive batches of ``batch_size`` (64);
  the rate per batch; mean and population std across batches weighted by batch size (the
  paper's +-).  With fewer than two batches that std is 0 whatever the episodes say, so the
  spread is then the half-width of the 95% Wilson score interval of the rate over the
  episodes (:func:`wilson_half_width`; ``rate_spread`` says which: ``"batches"`` or
  ``"wilson95"``), and ``<outcome>_ci`` holds the interval itself, in % (it is not centred on
  the rate: the table prints it);
* intervention rate, %: per episode ``active_sim_time / sim_time``; mean and population std
  across the episodes without an error.

Written once, with pandas: :func:`table_i` aggregates a DataFrame of episodes (as
:func:`rmm_bench.load_results` returns) into one row per agent; :func:`aggregate` gives the
same statistics for one agent's episodes as stored rows (dicts), which is what ``rmm-bench``'s
report and sweep use.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rmm_bench.store import RETRIED_ERRORS

__all__ = [
    "aggregate",
    "avoidable_collisions",
    "batch_rate",
    "rate_spread",
    "table_i",
    "weighted_mean_std",
    "wilson_half_width",
    "wilson_interval",
]

_NAN2 = (float("nan"), float("nan"))
_OUTCOMES = ("goal", "collision", "timeout")
_COLUMNS = (
    "steps",
    "compute_time",
    "decision_mean",
    "sim_time",
    "active_sim_time",
    "precompute_time",
    "final_speed",
    "qp_fallbacks",
    "nan_states",
)


def weighted_mean_std(values, weights) -> tuple[float, float]:
    v = np.asarray(values, float)
    w = np.asarray(weights, float)
    if v.size == 0 or w.sum() == 0:
        return _NAN2
    m = float(np.sum(w * v) / np.sum(w))
    return m, float(np.sqrt(np.sum(w * (v - m) ** 2) / np.sum(w)))


def wilson_half_width(p: float, n: int, z: float = 1.959963984540054) -> float:
    """Half the width of the Wilson score interval (95% for the default ``z``) of a rate ``p``
    observed over ``n`` episodes: ``z sqrt(p (1 - p) / n + z^2 / (4 n^2)) / (1 + z^2 / n)``.
    Unlike the normal approximation it is not 0 at ``p = 0`` or ``1``."""
    if n <= 0:
        return float("nan")
    return float(z * np.sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / (1.0 + z * z / n))


def wilson_interval(p: float, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The Wilson score interval ``(low, high)`` of a rate ``p`` over ``n`` episodes: centred on
    ``(p + z^2 / (2 n)) / (1 + z^2 / n)``, :func:`wilson_half_width` either side."""
    if n <= 0:
        return _NAN2
    centre = (p + z * z / (2.0 * n)) / (1.0 + z * z / n)
    w = wilson_half_width(p, n, z)
    return max(0.0, centre - w), min(1.0, centre + w)


def rate_spread(n: int, batch_size: int = 64) -> str:
    """Which spread :func:`batch_rate` gives for ``n`` episodes: ``"batches"`` (std over two or
    more batches) or ``"wilson95"`` (fewer: the Wilson half-width over episodes)."""
    return "batches" if n > batch_size else "wilson95"


def batch_rate(flags, batch_size: int = 64) -> tuple[float, float]:
    """Mean and spread of the rate of ``flags`` (in order): the std (weighted by batch size)
    of the per-batch rate over two or more batches, else :func:`wilson_half_width`."""
    import pandas as pd

    f = pd.Series(np.asarray(flags, float))
    if f.empty:
        return _NAN2
    if rate_spread(f.size, batch_size) == "wilson95":
        p = float(f.mean())
        return p, wilson_half_width(p, f.size)
    per_batch = f.groupby(np.arange(f.size) // batch_size).agg(["mean", "size"])
    return weighted_mean_std(per_batch["mean"], per_batch["size"])


def _mean_std(x) -> tuple[float, float]:
    x = np.asarray(x, float)
    if x.size == 0:
        return _NAN2
    return float(x.mean()), float(x.std())


def _aggregate_frame(df, batch_size: int) -> dict:
    """Table I statistics of one agent's episodes, a DataFrame with the store's episode columns."""
    missing = [c for c in _COLUMNS if c not in df.columns]  # e.g. an errored episode stores no timings
    if missing:
        df = df.assign(**{c: np.nan for c in missing})
    n = len(df)
    ok = df[df["outcome"] != "error"].sort_values("episode", kind="stable")
    out: dict[str, Any] = {"episodes": n, "errors": n - len(ok), "error_rate": (n - len(ok)) / n if n else float("nan")}
    error_kind = df["error_kind"] if "error_kind" in df.columns else None  # NULL: a guardian error (stored before it)
    no_result = (df["outcome"] == "error") & (error_kind.isin(RETRIED_ERRORS) if error_kind is not None else False)
    resulted = df[~no_result].sort_values("episode", kind="stable")  # guardian errors included: failures
    stepped = ok[ok["steps"] != 0]
    out["compute_ms"] = _mean_std(stepped["compute_time"] / stepped["steps"] * 1e3)
    out["decision_ms"] = _mean_std(ok["decision_mean"].dropna().astype(float) * 1e3)
    out["rate_spread"] = rate_spread(len(resulted), batch_size)  # the rates run over these episodes
    for name in _OUTCOMES:
        flags = (resulted["outcome"] == name).to_numpy(float)
        m, s = batch_rate(flags, batch_size)
        out[name] = (100 * m, 100 * s)
        lo, hi = wilson_interval(m, flags.size) if out["rate_spread"] == "wilson95" else _NAN2
        out[f"{name}_ci"] = (100 * lo, 100 * hi)
        out[f"total_{name}"] = 100 * float(flags.mean()) if flags.size else float("nan")
    timed = ok[ok["sim_time"] != 0]
    m, s = _mean_std(timed["active_sim_time"] / timed["sim_time"])
    out["intervention"] = (100 * m, 100 * s)
    out["steps"] = _mean_std(ok["steps"])
    out["precompute_s"] = _mean_std(ok["precompute_time"].astype(float).fillna(0.0))
    for col in ("qp_fallbacks", "nan_states"):
        out[col] = int(df[col].astype(float).fillna(0).sum())
    out["collision_speed"] = _mean_std(ok.loc[ok["outcome"] == "collision", "final_speed"].astype(float))
    return out


def aggregate(episodes: list[dict], batch_size: int = 64) -> dict:
    """Table I statistics of one agent's episodes (dicts with the store's episode fields)."""
    import pandas as pd

    episodes = list(episodes)
    if not episodes:
        return {
            "episodes": 0,
            "errors": 0,
            "error_rate": float("nan"),
            "compute_ms": _NAN2,
            "decision_ms": _NAN2,
            **{k: _NAN2 for k in _OUTCOMES},
            **{f"total_{k}": float("nan") for k in _OUTCOMES},
            "intervention": _NAN2,
            "steps": _NAN2,
            "precompute_s": _NAN2,
            "qp_fallbacks": 0,
            "nan_states": 0,
            "collision_speed": _NAN2,
            "rate_spread": "batches",
            **{f"{k}_ci": _NAN2 for k in _OUTCOMES},
        }
    return _aggregate_frame(pd.DataFrame.from_records(episodes), batch_size)


def avoidable_collisions(episodes: list[dict], doomed: dict[int, bool | None], batch_size: int = 64) -> dict:
    """The collision rate over the avoidable starts (the paper's collision rate with the starts no
    control could save left out), in %, as mean and spread over batches of ``batch_size`` of
    those episodes (or the Wilson half-width below two batches, as :func:`batch_rate`), and how
    many starts were doomed: ``{"avoidable_collision": (m, s), "avoidable_collision_ci",
    "avoidable_collision_spread", "doomed_starts": n, "avoidable_starts": n}``, or ``{}`` when
    a start among ``episodes`` was not assessed (``doomed``: episode -> the starts table's flag).
    Episodes without a result are left out, as in the other rates."""
    resulted = [
        e
        for e in sorted(episodes, key=lambda e: e["episode"])
        if not (e["outcome"] == "error" and (e.get("error_kind") or "guardian") in RETRIED_ERRORS)
    ]
    flags = [doomed.get(int(e["episode"])) for e in resulted]
    if not resulted or any(f is None for f in flags):
        return {}
    avoidable = [e for e, f in zip(resulted, flags, strict=True) if not f]
    m, s = batch_rate([e["outcome"] == "collision" for e in avoidable], batch_size) if avoidable else _NAN2
    spread = rate_spread(len(avoidable), batch_size)
    lo, hi = wilson_interval(m, len(avoidable)) if spread == "wilson95" and avoidable else _NAN2
    return {
        "avoidable_collision": (100 * m, 100 * s),
        "avoidable_collision_ci": (100 * lo, 100 * hi),
        "avoidable_collision_spread": spread,
        "doomed_starts": int(sum(bool(f) for f in flags)),
        "avoidable_starts": len(avoidable),
    }


def table_i(df, batch_size: int = 64):
    """Table I of a DataFrame of episodes (one row per stored episode, e.g. from
    :func:`rmm_bench.load_results`): one row per agent, in order of first appearance, with
    columns ``episodes``, ``errors``, ``<stat>`` and ``<stat>_std`` for each statistic of
    :func:`aggregate` that has a spread (``compute_ms``, ``goal``, ``collision``, ``timeout``,
    ``intervention``, ...), ``<outcome>_ci_low``/``_high`` (the Wilson interval, NaN over two or
    more batches), and the totals, counters and ``rate_spread`` as they are."""
    import pandas as pd

    rows = {}
    for agent, group in df.groupby("agent", sort=False):
        agg = _aggregate_frame(group, batch_size)
        row = {}
        for k, v in agg.items():
            if isinstance(v, tuple) and k.endswith("_ci"):  # a Wilson interval: its two ends
                row[f"{k}_low"], row[f"{k}_high"] = v
            elif isinstance(v, tuple):
                row[k], row[f"{k}_std"] = v
            else:
                row[k] = v
        rows[agent] = row
    return pd.DataFrame.from_dict(rows, orient="index").rename_axis("agent")
