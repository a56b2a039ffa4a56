"""The sampling-tree risk estimator (the paper's Algorithm 1), batched over the whole tree.

For a root state ``s`` the tree has branching factor ``n`` and depth ``m``: each node samples
``n`` controls from the policy, holds each for ``t`` seconds, and records the path at
``n_steps`` equally spaced points (point 0 is the parent).  A child whose path fails is worth 1
and is not expanded; a child at depth ``m`` that did not fail is worth 0 (or the scene's
``leaf_estimate`` with ``leaf="heuristic"``); every other node is worth the coherent risk
metric of its children.  A root that already fails is worth 1.  Also returned per root: the
minimum-risk child's first control, its hold time and the number of terminal nodes;
:meth:`RiskEstimator.estimate_candidates` labels given controls (action-conditioned labels).

Batching, the tree-size limit and randomness: :class:`RiskEstimator`; why:
docs/decisions/0008-risk-labels.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from rmm_envs.risk.metrics import get_metric
from rmm_envs.risk.protocol import check_scene

__all__ = ["MAX_TREE_NODES", "RiskEstimator", "RiskResult", "tree_nodes", "validate_tree_params"]

# The largest tree accepted per root state: 2^20 nodes, a thousand times the paper's
# n = 32, m = 2 (1056 nodes).  One root's deepest level alone then needs up to
# 2^20 * n_steps * state_dim * 8 bytes of paths (256 MiB for Dubins4D with 8 points), so
# anything larger cannot run on an ordinary machine; refusing it up front replaces a numpy
# MemoryError or an out-of-memory kill after the fact.
MAX_TREE_NODES = 2**20


def tree_nodes(branches: int, depth: int) -> int | float:
    """Nodes below one root, ``n + n^2 + ... + n^m``: exact, or ``inf`` beyond ``2^64``."""
    n, m = int(branches), int(depth)
    if n == 1:
        return m
    if m * math.log2(n) > 64:
        return math.inf
    return (n ** (m + 1) - n) // (n - 1)  # exact: integers


def validate_tree_params(branches, depth, horizon, n_steps, metric="expected", alpha=None, leaf="zero") -> None:
    """Raise ``ValueError`` naming the first tree parameter that is out of range.

    Checked before anything is allocated, including the tree's size (:data:`MAX_TREE_NODES`).
    """
    if int(branches) != branches or branches < 1:
        raise ValueError(f"branches (n) must be an integer >= 1, got {branches!r}")
    if int(depth) != depth or depth < 0:
        raise ValueError(f"depth (m) must be an integer >= 0, got {depth!r}")
    nodes = tree_nodes(branches, depth)
    if nodes > MAX_TREE_NODES:
        raise ValueError(
            f"branches (n, --branches) = {int(branches)} and depth (m, --depth) = {int(depth)} make a tree of "
            f"{'more than 2^64' if nodes == math.inf else f'{nodes:,}'} nodes per state (n + n^2 + ... + n^m); "
            f"at most {MAX_TREE_NODES:,} are supported "
            f"(the paper uses n = 32, m = 2: 1,056): lower --branches or --depth"
        )
    if not (isinstance(horizon, (int, float)) and horizon > 0 and math.isfinite(horizon)):
        raise ValueError(f"horizon (t) must be a finite number of seconds > 0, got {horizon!r}")
    if int(n_steps) != n_steps or n_steps < 2:
        raise ValueError(f"n_steps must be an integer >= 2, got {n_steps!r}")
    if leaf not in ("zero", "heuristic"):
        raise ValueError(f"leaf must be 'zero' or 'heuristic', got {leaf!r}")
    get_metric(metric, alpha)


def _propagate_failed(scene, states, controls, duration: float, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """``(failed (N,) bool, ends (N, d))`` of one tree level: the scene's ``propagate_failed``
    (a fused compiled loop), else ``path_failed`` of ``propagate`` and the paths' last points."""
    fused = getattr(scene, "propagate_failed", None)
    if fused is not None:
        failed, ends = fused(states, controls, duration, n_steps)
        return np.asarray(failed, dtype=bool), ends
    paths = scene.propagate(states, controls, duration, n_steps)
    return np.asarray(scene.path_failed(paths), dtype=bool), paths[:, -1]


def _children(parent_idx: np.ndarray, n: int) -> np.ndarray:
    """The indices of the ``n`` children of each of the nodes ``parent_idx``, parent by parent."""
    return (parent_idx[:, None] * n + np.arange(n)[None, :]).reshape(-1)


def _scale_into(r, lo, width):  # pragma: no cover - compiled
    """``r = lo + width * r`` over the last axis, in place: numpy's ``random_uniform``
    (``lower + range * next_double``), the same operations."""
    c = lo.shape[0]
    rows = r.reshape(-1, c)
    for i in range(rows.shape[0]):
        for j in range(c):
            rows[i, j] = lo[j] + width[j] * rows[i, j]


_scale_into = njit(cache=True)(_scale_into)


def uniform_box(rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray, size: tuple) -> np.ndarray:
    """``rng.uniform(lo, hi, size)`` for bounds ``lo``, ``hi`` of the last axis, the same draws
    in the same order and the same bits (``lo + (hi - lo) * u``, ``u`` from ``rng.random``), about
    three times faster (numpy's broadcast ``uniform`` costs 9 ns a number); a test pins the two."""
    width = np.subtract(hi, lo)
    if not isinstance(rng, np.random.Generator) or not np.all(np.isfinite(width)) or np.any(width < 0):
        return rng.uniform(lo, hi, size=size)  # another generator, or numpy's own refusal of the bounds
    r = rng.random(size)
    _scale_into(r, np.ascontiguousarray(lo, dtype=float), np.ascontiguousarray(width, dtype=float))
    return r


@dataclass
class RiskResult:
    risk: np.ndarray  # (B,)
    min_risk_ctrl: np.ndarray  # (B, c)
    min_risk_ctrl_dur: np.ndarray  # (B,)
    n_leaves: np.ndarray  # (B,) int


class RiskEstimator:
    """Batched Algorithm 1.

    All ``B * n`` branches of level 1 are one ``propagate`` and one ``path_failed`` call, all
    ``B * n^2`` of level 2 the next, and so on; roots are processed in chunks to bound memory.
    Only the children of live nodes are propagated (a failed node is not expanded), so the value
    is exactly Algorithm 1's and cluttered states cost less.  A tree of more than
    ``MAX_TREE_NODES`` (2^20) nodes per root is refused before anything is allocated.
    Randomness: the default policy (uniform over the control box) draws every control of the tree
    for all roots up front, level by level in root-major order, so results do not depend on the
    chunk size; a custom ``policy`` is called per chunk and level.  The minimum-risk child's
    control is held for ``t`` (the original stored one path segment's duration, ``t / (n_steps -
    1)``, of the same constant control).

    Args:
        scene: a :class:`rmm_envs.risk.RiskScene` (the dynamics in one obstacle configuration).
        branches: ``n >= 1``.  depth: ``m >= 0``.  horizon: ``t > 0`` seconds per level.
        n_steps: path points per branch, ``>= 2``.
        metric: ``"expected"`` (default), ``"cvar"`` (with ``alpha`` in (0, 1)) or ``"worst"``.
        policy: ``None`` for uniform controls, or ``policy(states (N, d), rng) -> (N, c)``.
        leaf: ``"zero"`` (Algorithm 1) or ``"heuristic"`` (the scene's ``leaf_estimate``).
        chunk_size: roots per batch (memory ~ chunk * n^m * n_steps * d * 8 bytes).
        fused: ``True`` (default) runs a tree level through the scene's ``propagate_failed`` where
            it has one (a compiled loop that propagates and tests each branch, the same bits);
            ``False`` the separate ``propagate`` and ``path_failed``, the reference it is pinned to.
    """

    def __init__(
        self,
        scene,
        branches: int = 32,
        depth: int = 2,
        horizon: float = 2.0,
        n_steps: int = 8,
        metric: str = "expected",
        alpha: float | None = None,
        policy: Callable | None = None,
        leaf: str = "zero",
        chunk_size: int | None = None,
        fused: bool = True,
    ) -> None:
        check_scene(scene)
        validate_tree_params(branches, depth, horizon, n_steps, metric, alpha, leaf)
        if leaf == "heuristic" and not hasattr(scene, "leaf_estimate"):
            raise TypeError(f"leaf='heuristic' needs {type(scene).__name__}.leaf_estimate(states)")
        if policy is not None and not callable(policy):
            raise TypeError(f"policy must be callable policy(states, rng) -> controls, got {policy!r}")
        self.reduce = get_metric(metric, alpha)
        self.scene = scene
        self.n = int(branches)
        self.m = int(depth)
        self.t = float(horizon)
        self.n_steps = int(n_steps)
        self.metric = metric
        self.alpha = alpha
        self.policy = policy
        self.leaf = leaf
        self.fused = bool(fused)
        nodes = self.n**self.m if self.m else 1  # exact: integers
        self.chunk_size = int(chunk_size) if chunk_size else max(1, 32768 // max(nodes, 1))

    def params(self) -> dict:
        return {
            "branches": self.n,
            "depth": self.m,
            "horizon": self.t,
            "n_steps": self.n_steps,
            "metric": self.metric,
            "alpha": self.alpha,
            "leaf": self.leaf,
            "policy": "uniform" if self.policy is None else getattr(self.policy, "__name__", repr(self.policy)),
        }

    # ------------------------------------------------------------------
    def draw_controls(self, rng: np.random.Generator, n_roots: int) -> list[np.ndarray]:
        """Uniform controls for every level: level ``l`` has shape ``(n_roots, n^l, c)``."""
        lo, hi = np.asarray(self.scene.control_low, float), np.asarray(self.scene.control_high, float)
        widths = [self.n ** (lvl + 1) for lvl in range(self.m)]  # exact: integers
        if not self.fused:
            return [rng.uniform(lo, hi, size=(n_roots, w, lo.shape[0])) for w in widths]
        return [uniform_box(rng, lo, hi, (n_roots, w, lo.shape[0])) for w in widths]

    def estimate(
        self, states, rng: np.random.Generator | None = None, controls: list[np.ndarray] | None = None
    ) -> RiskResult:
        """Estimate the risk of each root state ``(B, d)``.

        ``controls`` (optional) gives every control of the tree, as :meth:`draw_controls`
        returns; otherwise they are drawn from ``rng`` (required then).
        """
        states = np.asarray(states, dtype=float)
        if states.ndim != 2 or states.shape[1] != self.scene.state_dim:
            raise ValueError(f"states must have shape (B, {self.scene.state_dim}), got {states.shape}")
        if not np.all(np.isfinite(states)):
            raise ValueError("states must be finite")
        B = states.shape[0]
        if controls is None and self.policy is None and self.m > 0:
            if rng is None:
                raise ValueError("estimate() needs rng (a numpy Generator) or explicit controls")
            controls = self.draw_controls(rng, B)
        if controls is not None:
            if len(controls) != self.m:
                raise ValueError(f"controls must have one array per level ({self.m}), got {len(controls)}")
            for lvl, c in enumerate(controls):
                if c.shape[:2] != (B, self.n ** (lvl + 1)):  # exact: integers
                    width = self.n ** (lvl + 1)  # exact: integers
                    raise ValueError(f"controls[{lvl}] must have shape ({B}, {width}, c), got {c.shape}")
        elif self.m > 0 and rng is None:
            raise ValueError("estimate() needs rng (a numpy Generator) for a custom policy")

        c_dim = len(np.asarray(self.scene.control_low))
        out = RiskResult(np.empty(B), np.zeros((B, c_dim)), np.zeros(B), np.zeros(B, dtype=np.int64))
        for lo in range(0, B, self.chunk_size):
            hi = min(B, lo + self.chunk_size)
            ctl = None if controls is None else [c[lo:hi] for c in controls]
            r = self._estimate_chunk(states[lo:hi], rng, ctl)
            out.risk[lo:hi], out.min_risk_ctrl[lo:hi], out.min_risk_ctrl_dur[lo:hi], out.n_leaves[lo:hi] = r
        return out

    def estimate_candidates(self, states, candidates, hold: float, rng: np.random.Generator) -> np.ndarray:
        """Risk ``(B, K)`` of holding each candidate control ``(K, c)`` for ``hold`` seconds
        from each root state ``(B, d)``, then running the tree from the end of that branch.

        A root that already fails, or a candidate branch that fails, is worth 1.  The tree's
        controls are drawn from ``rng`` for the live end states in root-major, candidate-minor
        order, so the result does not depend on the chunk size.
        """
        states = np.asarray(states, dtype=float)
        cands = np.asarray(candidates, dtype=float)
        c_dim = len(np.asarray(self.scene.control_low))
        if states.ndim != 2 or states.shape[1] != self.scene.state_dim:
            raise ValueError(f"states must have shape (B, {self.scene.state_dim}), got {states.shape}")
        if cands.ndim != 2 or cands.shape[1] != c_dim or cands.shape[0] < 1:
            raise ValueError(f"candidates must have shape (K >= 1, {c_dim}), got {cands.shape}")
        if not np.all(np.isfinite(cands)):
            raise ValueError(f"candidates must be finite, got {cands.tolist()}")
        lo, hi = np.asarray(self.scene.control_low, float), np.asarray(self.scene.control_high, float)
        if np.any(cands < lo) or np.any(cands > hi):
            raise ValueError(f"candidates {cands.tolist()} fall outside the control box [{lo.tolist()}, {hi.tolist()}]")
        if not (isinstance(hold, (int, float)) and math.isfinite(hold) and hold > 0):
            raise ValueError(f"hold must be a finite number of seconds > 0, got {hold!r}")
        B, K = states.shape[0], cands.shape[0]
        rep = np.repeat(states, K, axis=0)
        u = np.tile(cands, (B, 1))
        risk = np.ones(B * K)
        root_ok = ~np.asarray(self.scene.state_failed(rep), dtype=bool)
        if root_ok.any():
            if self.fused:
                failed, last = _propagate_failed(self.scene, rep[root_ok], u[root_ok], float(hold), self.n_steps)
                branch_ok = ~failed
                ends = np.compress(branch_ok, last, axis=0)
            else:
                paths = self.scene.propagate(rep[root_ok], u[root_ok], float(hold), self.n_steps)
                branch_ok = ~np.asarray(self.scene.path_failed(paths), dtype=bool)
                ends = paths[branch_ok, -1]
            ok = np.zeros(B * K, dtype=bool)
            ok[root_ok] = branch_ok
            if ends.shape[0]:
                risk[ok] = self.estimate(ends, rng).risk
        return risk.reshape(B, K)

    def _estimate_chunk(self, roots: np.ndarray, rng, controls):
        sys_ = self.scene
        n, m = self.n, self.m
        B = roots.shape[0]
        root_fail = np.asarray(sys_.state_failed(roots), dtype=bool)
        c_dim = len(np.asarray(sys_.control_low))
        if m == 0:
            risk = root_fail.astype(float)
            if self.leaf == "heuristic":
                risk = np.where(root_fail, 1.0, sys_.leaf_estimate(roots))
            return risk, np.zeros((B, c_dim)), np.zeros(B), np.zeros(B, dtype=np.int64)

        # Expand level by level; only the children of live (non-failed) nodes are propagated, n
        # of them per live parent (parent_idx: the parents' indices in their level, root-major).
        # A level's bookkeeping works on those blocks of n; the last level keeps only its failures.
        parents, parent_idx = np.compress(~root_fail, roots, axis=0), np.flatnonzero(~root_fail)
        fails: list[np.ndarray] = []
        final, final_idx = None, parent_idx[:0]
        first_ctrls: np.ndarray | None = None
        leaves = np.zeros(B, dtype=np.int64)  # terminal nodes (failed, or at depth m) among the expanded ones
        for lvl in range(m):
            n_nodes = B * n ** (lvl + 1)  # exact: integers
            last = lvl == m - 1
            rep = np.repeat(parents, n, axis=0)
            if controls is not None:
                c = controls[lvl].shape[-1]
                if self.fused:  # take the parents' blocks: the same rows as the children's, faster
                    u = np.take(controls[lvl].reshape(-1, n, c), parent_idx, axis=0).reshape(-1, c)
                else:
                    u = controls[lvl].reshape(-1, c)[_children(parent_idx, n)]
            else:
                assert self.policy is not None  # estimate() draws the controls up front for a uniform policy
                u = np.asarray(self.policy(rep, rng), dtype=float)
                if u.shape != (rep.shape[0], c_dim):
                    raise ValueError(f"policy returned shape {u.shape}, expected {(rep.shape[0], c_dim)}")
            if lvl == 0:
                first_ctrls = np.zeros((n_nodes, c_dim))
                first_ctrls.reshape(-1, n, c_dim)[parent_idx] = u.reshape(-1, n, c_dim)
            if last:  # every expanded node of the last level is terminal
                leaves += n * np.bincount(parent_idx // n**lvl, minlength=B)  # exact: integers
            fail = np.zeros(n_nodes, dtype=bool)
            if rep.shape[0]:
                if self.fused:  # the scene's fused loop where it has one; compress: faster masks
                    f, ends = _propagate_failed(sys_, rep, u, self.t, self.n_steps)
                else:
                    paths = sys_.propagate(rep, u, self.t, self.n_steps)
                    f = np.asarray(sys_.path_failed(paths), dtype=bool)
                    ends = paths[:, -1]
                fail.reshape(-1, n)[parent_idx] = f.reshape(-1, n)
                if not last or self.leaf == "heuristic":  # the live children: the next level's parents
                    parents = np.compress(~f, ends, axis=0)
                    parent_idx = np.compress(~f, _children(parent_idx, n))
                    if last:
                        final, final_idx = parents, parent_idx
            else:
                parent_idx = parent_idx[:0]
            if not last:
                leaves += fail.reshape(B, -1).sum(axis=1)
            fails.append(fail)

        # values, bottom-up (nodes that were never expanded are masked by their failed ancestor)
        value = fails[-1].astype(float)
        if self.leaf == "heuristic" and final_idx.size:
            value[final_idx] = sys_.leaf_estimate(final)
        for lvl in range(m - 2, -1, -1):
            value = np.where(fails[lvl], 1.0, self.reduce(value.reshape(-1, n)))
        child_values = value.reshape(B, n)
        risk = np.where(root_fail, 1.0, self.reduce(child_values))

        best = np.argmin(child_values, axis=1)
        assert first_ctrls is not None  # set at level 0, and m >= 1 here
        min_ctrl = first_ctrls.reshape(B, n, -1)[np.arange(B), best]
        min_ctrl = np.where(root_fail[:, None], 0.0, min_ctrl)
        dur = np.where(root_fail, 0.0, self.t)

        return risk, min_ctrl, dur, leaves
