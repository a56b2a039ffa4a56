"""Table I aggregation (docs/original-code.md, item 22), over the non-errored episodes in order.

* policy compute time, ms: per episode ``compute_time / steps``; mean and population std
  across episodes;
* success / collision / timeout rate, %: episodes split in order into consecutive batches of
  ``batch_size`` (64); the rate per batch; mean and population std across batches weighted by
  batch size (the paper's +-);
* intervention rate, %: per episode ``active_sim_time / sim_time``; mean and population std
  across episodes.
"""

from __future__ import annotations

import numpy as np

__all__ = ["aggregate", "batch_rate", "weighted_mean_std"]


def weighted_mean_std(values, weights) -> tuple[float, float]:
    v = np.asarray(values, float)
    w = np.asarray(weights, float)
    if v.size == 0 or w.sum() == 0:
        return float("nan"), float("nan")
    m = float(np.sum(w * v) / np.sum(w))
    return m, float(np.sqrt(np.sum(w * (v - m) ** 2) / np.sum(w)))


def batch_rate(flags, batch_size: int = 64) -> tuple[float, float]:
    """Mean and std (weighted by batch size) of the per-batch rate of ``flags`` (in order)."""
    f = np.asarray(flags, float)
    if f.size == 0:
        return float("nan"), float("nan")
    chunks = [f[i:i + batch_size] for i in range(0, f.size, batch_size)]
    return weighted_mean_std([c.mean() for c in chunks], [c.size for c in chunks])


def _mean_std(x) -> tuple[float, float]:
    x = np.asarray(x, float)
    if x.size == 0:
        return float("nan"), float("nan")
    return float(x.mean()), float(x.std())


def aggregate(episodes: list[dict], batch_size: int = 64) -> dict:
    """Table I statistics of one agent's episodes (dicts with the store's episode fields)."""
    ok = [e for e in sorted(episodes, key=lambda e: e["episode"]) if e["outcome"] != "error"]
    n_err = len(episodes) - len(ok)
    out = {"episodes": len(episodes), "errors": n_err, "error_rate": n_err / len(episodes) if episodes else float("nan")}
    comp = [e["compute_time"] / e["steps"] * 1e3 for e in ok if e["steps"]]
    out["compute_ms"] = _mean_std(comp)
    dec = [e["decision_mean"] * 1e3 for e in ok if e.get("decision_mean") is not None]
    out["decision_ms"] = _mean_std(dec)
    for name in ("goal", "collision", "timeout"):
        flags = [e["outcome"] == name for e in ok]
        m, s = batch_rate(flags, batch_size)
        out[name] = (100 * m, 100 * s)
        out[f"total_{name}"] = 100 * float(np.mean(flags)) if flags else float("nan")
    ratio = [e["active_sim_time"] / e["sim_time"] for e in ok if e["sim_time"]]
    m, s = _mean_std(ratio)
    out["intervention"] = (100 * m, 100 * s)
    out["steps"] = _mean_std([e["steps"] for e in ok])
    out["precompute_s"] = _mean_std([e["precompute_time"] or 0.0 for e in ok])
    out["qp_fallbacks"] = int(sum(e.get("qp_fallbacks") or 0 for e in episodes))
    out["nan_states"] = int(sum(e.get("nan_states") or 0 for e in episodes))
    coll = [e["final_speed"] for e in ok if e["outcome"] == "collision"]
    out["collision_speed"] = _mean_std(coll)
    return out
