"""The LRMM network's inference, compiled: :func:`forward_one` for one observation (a guardian's
per-decision path) and :func:`forward_rows` for a batch, row by row through the same code, so a
batch gives the bits of its rows.  Sums run in a fixed order and the activations call the C
library, so neither depends on the CPU's BLAS kernel or numpy's SIMD code.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["forward_one", "forward_rows"]


def forward_one(x, Ws, bs, act_code):
    """The network at one observation ``x`` (``Ws``: transposed weights, the scaler folded into
    the first; ``bs``: biases): hidden layers with
    activation ``ACTIVATIONS[act_code]``, a sigmoid output; ``None`` if ``x`` is not finite."""
    for i in range(x.shape[0]):
        if not math.isfinite(x[i]):
            return None
    h = x
    last = len(Ws) - 1
    for layer in range(len(Ws)):
        WT = Ws[layer]  # (inputs, outputs): the inner loop runs along contiguous outputs
        b = bs[layer]
        n_out = WT.shape[1]
        z = np.zeros(n_out)
        for k in range(WT.shape[0]):
            hk = h[k]
            for j in range(n_out):
                z[j] += WT[k, j] * hk
        for j in range(n_out):
            acc = z[j] + b[j]  # after the products, as numpy's ``x @ W.T + b``
            if layer == last or act_code == 0:
                acc = 1.0 / (1.0 + math.exp(-acc))
            elif act_code == 1:
                acc = math.tanh(acc)
            elif act_code == 2:
                acc = max(acc, 0.0)
            elif acc <= 0.0:
                acc = math.expm1(acc)
            z[j] = acc
        h = z
    return h


forward_one = njit(cache=True)(forward_one)


def forward_rows(X, Ws, bs, act_code):
    """:func:`forward_one` of every (finite) row of ``X``: the batch path computes the same
    bits as the one-observation path, in sums of a fixed order (no BLAS, whose kernel and so
    whose rounding depends on the CPU); a row that is not finite gives NaN.  Element by element:
    a whole-row assignment makes numba compile its shape-mismatch message, 3 of the 4.5 s this
    function took to compile."""
    out = np.empty((X.shape[0], bs[len(bs) - 1].shape[0]))
    for i in range(X.shape[0]):
        h = forward_one(X[i], Ws, bs, act_code)
        for j in range(out.shape[1]):
            out[i, j] = np.nan if h is None else h[j]
    return out


forward_rows = njit(cache=True)(forward_rows)
