"""The LRMM network at inference time (numpy only) and its artifact format.

Network: ``x_scaled = (obs[features] - data_min) * scale`` (a MinMax scaler fitted on the
training split only), then ``len(hidden)`` layers ``act(W x + b)``, then an output layer
``sigmoid(W x [+ b])`` giving the inferred risk in ``(0, 1)``; format version 2 optionally adds
one output unit per candidate control (the action-conditioned head).  Artifact: one ``.npz``
file loaded with ``allow_pickle=False`` (no code runs on load): the scaler, the weights and a
JSON ``meta`` document, with a checksum over every array verified on load.  Every array must be
finite: a model with NaN or inf weights raises ``ValueError`` naming the array.

The shipped models' table (:data:`SHIPPED_BY_SYSTEM`, :data:`SHIPPED`, :func:`default_model_path`)
lives in :mod:`rmm_guardians.lrmm.shipped`; this module re-exports it.

The head, the artifact's fields and why: docs/decisions/0007-datasets-and-models.md.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from rmm_envs.catalog import FORMER_IDS, current_id
from rmm_envs.defaults import DEFAULT_LABELLED_ENV
from rmm_envs.machine_independent import matvec
from rmm_guardians.lrmm.inference import forward_one as _forward_one
from rmm_guardians.lrmm.inference import forward_rows as _forward_rows
from rmm_guardians.lrmm.shipped import SHIPPED, SHIPPED_BY_SYSTEM, Shipped, default_model_path

__all__ = ["FORMAT", "SHIPPED", "SHIPPED_BY_SYSTEM", "LRMMModel", "Shipped", "default_model_path", "load_model"]

FORMAT = "rmm-lrmm-model"
FORMAT_VERSION = 2
READABLE_VERSIONS = (1, 2)  # version 1: one output unit, no candidates or decision fields
ACTIVATIONS = ("sigmoid", "tanh", "relu", "elu")


def _checksum(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _real(name: str, values) -> np.ndarray:
    """``values`` as a float array; ``ValueError`` naming the array if they are not real numbers
    (a complex array would lose its imaginary part in silence)."""
    a = np.asarray(values)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"LRMM model array {name!r} has dtype {a.dtype}; expected real numbers (float)")
    return a.astype(float, copy=False)


class LRMMModel:
    """A trained risk network ready for numpy inference.

    Args:
        weights: ``[(W, b), ...]`` for hidden layers then the output layer (``b`` may be None
            for the output).  scaler_min, scaler_scale: per selected feature.
        meta: the metadata dictionary (see the module docstring).
    """

    # set on some models only (absent otherwise; read with getattr): ``load`` sets the file and the
    # SHA-256 of its bytes, ``rmm_guardians.lrmm.train.train`` the torch network (for tests)
    path: Path
    file_sha256: str
    torch_net: Any

    def __init__(self, weights, scaler_min, scaler_scale, meta: dict) -> None:
        self.weights = [
            (_real(f"W{i}", W), None if b is None else _real(f"b{i}", b)) for i, (W, b) in enumerate(weights)
        ]
        self.scaler_min = _real("scaler_min", scaler_min)
        self.scaler_scale = _real("scaler_scale", scaler_scale)
        self.meta = dict(meta)
        missing = [k for k in ("features", "obs_dim") if k not in self.meta]
        if missing:
            raise ValueError(f"metadata lacks {missing}: not a complete LRMM model")
        self.features = np.asarray(self.meta["features"], dtype=int)
        self.obs_dim = int(self.meta["obs_dim"])
        self.env_id = self.meta.get("env_id")
        act = self.meta.get("activation", "sigmoid")
        if act not in ACTIVATIONS:
            raise ValueError(f"unknown activation {act!r}; expected one of {ACTIVATIONS}")
        cands = self.meta.get("candidates")
        self.candidates = None if cands is None else np.asarray(cands, dtype=float)
        self.candidate_hold = self.meta.get("candidate_hold")
        hold = self.candidate_hold
        if hold is not None and (
            isinstance(hold, bool) or not isinstance(hold, (int, float)) or not 0 < hold < math.inf
        ):
            raise ValueError(f"meta 'candidate_hold' must be a finite number of seconds > 0, got {hold!r}")
        self._check_shapes()
        self._check_finite()
        # fold the scaler into the first layer: W0 ((x - m) * s) + b0 = (W0 * s) x + (b0 - W0 (m s))
        W0, b0 = self.weights[0]
        self._W0 = W0 * self.scaler_scale[None, :]
        self._b0 = (b0 if b0 is not None else 0.0) - matvec(self._W0, self.scaler_min)
        self._all_features = self.features.shape[0] == self.obs_dim and np.array_equal(
            self.features, np.arange(self.obs_dim)
        )
        # the compiled one-observation path: the layers as tuples (a missing bias as zeros)
        layers = [(self._W0, np.broadcast_to(self._b0, (self._W0.shape[0],)))] + [
            (W, b if b is not None else np.zeros(W.shape[0])) for W, b in self.weights[1:]
        ]
        self._Ws = tuple(np.array(W.T, dtype=float, order="C") for W, _ in layers)  # transposed
        self._bs = tuple(np.array(b, dtype=float, order="C") for _, b in layers)
        self._act_code = ACTIVATIONS.index(act)

    def _check_shapes(self) -> None:
        n_in = self.features.shape[0]
        if len(self.weights) < 2:
            raise ValueError(f"an LRMM network needs at least one hidden layer, got {len(self.weights) - 1}")
        if self.scaler_min.shape != (n_in,) or self.scaler_scale.shape != (n_in,):
            raise ValueError(f"scaler has shape {self.scaler_min.shape}/{self.scaler_scale.shape}, expected ({n_in},)")
        if np.any(self.features < 0) or np.any(self.features >= self.obs_dim):
            raise ValueError(f"feature indices {self.features.tolist()} fall outside an observation of {self.obs_dim}")
        prev = n_in
        for i, (W, b) in enumerate(self.weights):
            if W.ndim != 2 or W.shape[1] != prev:
                raise ValueError(f"layer {i}: weight shape {W.shape} does not take {prev} inputs")
            if b is not None and b.shape != (W.shape[0],):
                raise ValueError(f"layer {i}: bias shape {b.shape}, expected ({W.shape[0]},)")
            prev = W.shape[0]
        n_out = 1 if self.candidates is None else 1 + self.candidates.shape[0]
        if self.candidates is not None and (self.candidates.ndim != 2 or self.candidates.shape[0] < 1):
            raise ValueError(f"meta 'candidates' must be a non-empty list of controls, got {self.meta['candidates']!r}")
        if prev != n_out:
            what = "one unit (risk)" if self.candidates is None else f"{n_out} units (risk + {n_out - 1} candidates)"
            raise ValueError(f"the output layer must have {what}, got {prev}")
        self.n_outputs = n_out

    def _check_finite(self) -> None:
        for name, a in self.arrays().items():
            if not np.all(np.isfinite(a)):
                raise ValueError(
                    f"LRMM model array {name!r} holds {int(np.sum(~np.isfinite(a)))} non-finite value(s) (NaN or inf); "
                    "the training diverged or the file is damaged"
                )
        if self.candidates is not None and (
            self.candidates.dtype.kind not in "fiu" or not np.all(np.isfinite(self.candidates))
        ):
            raise ValueError(f"meta 'candidates' holds non-finite controls: {self.candidates.tolist()}")

    # ------------------------------------------------------------------ inference
    def predict(self, obs) -> np.ndarray | float:
        """Inferred risk for one observation ``(obs_dim,)`` (a float) or a batch ``(N, obs_dim)``."""
        out = self.predict_all(obs)[..., 0]
        return float(out) if out.ndim == 0 else out

    def predict_all(self, obs) -> np.ndarray:
        """All output units, ``(n_outputs,)`` or ``(N, n_outputs)``: the risk, then one risk per
        candidate control (version-2 models with a head)."""
        x = np.asarray(obs, dtype=float)
        single = x.ndim == 1
        if x.shape[-1] != self.obs_dim or x.ndim not in (1, 2):
            raise ValueError(f"observation must have shape ({self.obs_dim},) or (N, {self.obs_dim}), got {x.shape}")
        if single:
            # one compiled call (a guardian's per-decision inference): numpy's per-call overhead
            # on 64-unit layers was most of the decision time.
            if not self._all_features:
                x = x[self.features]
            out = _forward_one(np.ascontiguousarray(x), self._Ws, self._bs, self._act_code)
            if out is None:
                raise ValueError(f"observation contains NaN or inf: {np.asarray(obs, dtype=float).tolist()}")
            return out
        if not self._all_features:
            x = x[..., self.features]  # as the one-observation path: only the model's inputs must be finite
        bad = np.flatnonzero(~np.isfinite(x).all(axis=1))
        if bad.size:
            raise ValueError(
                f"observation {int(bad[0])} of the batch contains NaN or inf ({bad.size} rows do): "
                f"{np.asarray(obs, dtype=float)[bad[0]].tolist()}"
            )
        # the same compiled sums row by row: the bits of a batch equal those of its rows, and
        # neither depends on the CPU (numpy's ``@`` goes to BLAS, ``np.exp`` to SIMD code)
        return _forward_rows(np.ascontiguousarray(x), self._Ws, self._bs, self._act_code)

    # ------------------------------------------------------------------ I/O
    def arrays(self) -> dict[str, np.ndarray]:
        arrs = {"scaler_min": self.scaler_min, "scaler_scale": self.scaler_scale}
        for i, (W, b) in enumerate(self.weights):
            arrs[f"W{i}"] = W
            if b is not None:
                arrs[f"b{i}"] = b
        return arrs

    def save(self, path) -> Path:
        """Write the artifact atomically (temporary file, then rename)."""
        path = Path(path)
        self._check_finite()
        arrs = self.arrays()
        meta = dict(self.meta)
        meta["format"], meta["format_version"] = FORMAT, FORMAT_VERSION
        meta["weights_sha256"] = _checksum(arrs)
        buf = io.BytesIO()
        np.savez(
            buf,
            meta=np.frombuffer(json.dumps(meta, indent=1, sort_keys=True).encode(), dtype=np.uint8),
            **arrs,  # type: ignore[arg-type]  # numpy's stub lets **arrays reach allow_pickle; none is so named
        )
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp")
        tmp.write_bytes(buf.getvalue())
        tmp.replace(path)
        self.meta = meta
        return path

    @classmethod
    def load(cls, path, env_id: str | None = None, obs_dim: int | None = None) -> LRMMModel:
        """Load and verify an artifact; ``env_id``/``obs_dim`` (optional) must match it."""
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"LRMM model file {path} does not exist")
        try:
            data = path.read_bytes()  # read once: the digest is of exactly the bytes the model is built from
            with np.load(io.BytesIO(data), allow_pickle=False) as z:
                arrays = {k: z[k] for k in z.files}
        except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
            raise ValueError(f"{path} is not a readable LRMM model (truncated or not an .npz file: {e})") from None
        if "meta" not in arrays:
            raise ValueError(f"{path} has no 'meta' entry: not an LRMM model file")
        try:
            meta = json.loads(arrays.pop("meta").tobytes().decode())
        except (UnicodeDecodeError, json.JSONDecodeError) as e:
            raise ValueError(f"{path}: metadata is not valid JSON ({e})") from None
        if meta.get("format") != FORMAT or meta.get("format_version") not in READABLE_VERSIONS:
            raise ValueError(
                f"{path}: expected format {FORMAT} v{'/'.join(map(str, READABLE_VERSIONS))}, "
                f"got {meta.get('format')} v{meta.get('format_version')}"
            )
        if meta["format_version"] == 1:
            for key in ("candidates", "decision"):
                if key in meta:
                    raise ValueError(f"{path}: field {key!r} needs format version 2, the file says version 1")
        if _checksum(arrays) != meta.get("weights_sha256"):
            raise ValueError(f"{path}: weights checksum mismatch (the file is corrupted or was edited)")
        trained = meta.get("env_id")
        now = f" (now {FORMER_IDS[trained]!r})" if trained in FORMER_IDS else ""
        if env_id is not None and current_id(str(trained)) != current_id(env_id):  # a former id is today's id's env
            raise ValueError(f"{path} was trained for env {trained!r}{now}, not {env_id!r}")
        if obs_dim is not None and int(meta.get("obs_dim", -1)) != int(obs_dim):
            raise ValueError(f"{path} expects observations of {meta.get('obs_dim')} values, the env gives {obs_dim}")
        missing = [k for k in ("hidden", "features", "obs_dim") if k not in meta]
        if missing:
            raise ValueError(f"{path}: metadata lacks {missing}: not a complete LRMM model file")
        if not isinstance(meta["hidden"], list) or len(meta["hidden"]) > 64:
            raise ValueError(f"{path}: metadata 'hidden' must be a list of layer widths, got {meta['hidden']!r}"[:300])
        n_layers = len(meta["hidden"]) + 1
        weights = []
        for i in range(n_layers):
            if f"W{i}" not in arrays:
                raise ValueError(f"{path}: missing weight array W{i}")
            weights.append((arrays[f"W{i}"], arrays.get(f"b{i}")))
        try:
            model = cls(weights, arrays["scaler_min"], arrays["scaler_scale"], meta)
        except ValueError as e:
            raise ValueError(f"{path}: {e}") from None
        model.path = path
        model.file_sha256 = hashlib.sha256(data).hexdigest()
        return model


def load_model(path=None, env_id: str = DEFAULT_LABELLED_ENV) -> LRMMModel:
    """Load ``path`` or the shipped model for ``env_id``."""
    return LRMMModel.load(path or default_model_path(env_id))
