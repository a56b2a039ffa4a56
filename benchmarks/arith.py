"""Machines' arithmetic, simulated on one machine, for ``benchmarks/check_behaviour.py arith`` and
``tests/test_reproducibility.py``: the settings to compare, running the fingerprint in a fresh
interpreter under one of them, and reading back what arithmetic a process really runs under.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["PRE_FMA", "applied", "arith_settings", "describe", "run_under"]


# Machines' arithmetic, simulated on one machine: the BLAS kernel numpy's OpenBLAS picks
# (OPENBLAS_CORETYPE), the CPU numba compiles for (NUMBA_CPU_NAME; unset = this host) and the
# SIMD loops numpy dispatches to (NPY_DISABLE_CPU_FEATURES: X86_V4 is AVX-512, X86_V3 AVX2/FMA).
_NPY_NO_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"
_NPY_NO_AVX2 = "X86_V3 " + _NPY_NO_AVX512


#: every environment variable that changes which arithmetic a process runs; ``run_under`` sets
#: those a setting names and clears the rest
_ARITH_VARIABLES = (
    "OPENBLAS_CORETYPE",
    "OPENBLAS_L2_SIZE",
    "NUMBA_CPU_NAME",
    "NUMBA_CPU_FEATURES",
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "GLIBC_TUNABLES",
    "ATEN_CPU_CAPABILITY",
)


def arith_settings(host_flags: set[str] | None = None) -> list[dict]:
    """The settings to compare, the portable one (oldest kernel, generic CPU, no SIMD dispatch) first."""
    if host_flags is None:
        try:
            host_flags = set(Path("/proc/cpuinfo").read_text().split())
        except OSError:
            host_flags = set()
    out = [
        {"OPENBLAS_CORETYPE": "Prescott", "NUMBA_CPU_NAME": "generic", "NPY_DISABLE_CPU_FEATURES": _NPY_NO_AVX2},
        {"OPENBLAS_CORETYPE": "Haswell", "NUMBA_CPU_NAME": "generic", "NPY_DISABLE_CPU_FEATURES": _NPY_NO_AVX512},
        {"OPENBLAS_CORETYPE": "Haswell", "NUMBA_CPU_NAME": None, "NPY_DISABLE_CPU_FEATURES": _NPY_NO_AVX512},
        {"OPENBLAS_CORETYPE": None, "NUMBA_CPU_NAME": None, "NPY_DISABLE_CPU_FEATURES": None},
    ]  # the host's own
    if "avx512f" in host_flags:
        out.insert(3, {"OPENBLAS_CORETYPE": "SkylakeX", "NUMBA_CPU_NAME": None, "NPY_DISABLE_CPU_FEATURES": None})
    return out


#: a CPU without FMA (before Intel Haswell / AMD Piledriver): the C library's exp, log, sin,
#: cos, atan2, ... then run other code (glibc picks FMA variants per CPU).  Not bit-identical;
#: ``arith --pre-fma`` measures how far results move (docs/reproduction.md).
PRE_FMA = {
    "OPENBLAS_CORETYPE": "Prescott",
    "NUMBA_CPU_NAME": "generic",
    "NPY_DISABLE_CPU_FEATURES": _NPY_NO_AVX2,
    "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-FMA4,-AVX512F",
}


def describe(setting: dict) -> str:
    return ", ".join(f"{k}={'(host)' if v is None else v}" for k, v in setting.items())


def run_under(setting: dict, size: str, timeout: float | None = None) -> dict:
    """The fingerprint computed in a fresh interpreter under one setting (None: unset)."""
    env = {k: v for k, v in os.environ.items() if k not in _ARITH_VARIABLES}  # none leaks in from this shell
    env.update({k: v for k, v in setting.items() if v is not None})
    script = Path(__file__).resolve().with_name("check_behaviour.py")
    root = script.parent.parent
    env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "fingerprint.json"
        proc = subprocess.run(
            [sys.executable, str(script), "record", str(out), "--size", size],
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
            cwd=root,
        )
        if proc.returncode != 0:
            raise RuntimeError(
                f"fingerprint under {describe(setting)} failed ({proc.returncode}):\n{proc.stderr[-3000:]}"
            )
        return json.loads(out.read_text())


def applied() -> dict:
    """The arithmetic this interpreter really runs under: numpy's dispatch target of float64
    ``exp`` and ``arctan2``, the OpenBLAS kernel numpy's BLAS picked (None where it cannot be
    read: another BLAS), and the target numba compiles for."""
    import ctypes
    import glob

    import numba

    info = np.lib.introspect.opt_func_info(func_name="^(exp|arctan2)$", signature="float64")
    out = {f"numpy_{k}": next(iter(v.values()))["current"] for k, v in sorted(info.items())}
    out["blas_core"] = None
    for lib in glob.glob(os.path.join(os.path.dirname(np.__file__), os.pardir, "numpy.libs", "*openblas*")):
        for name in ("scipy_openblas_get_corename64_", "openblas_get_corename64_", "openblas_get_corename"):
            try:
                fn = getattr(ctypes.CDLL(lib), name)
            except (OSError, AttributeError):
                continue
            fn.restype = ctypes.c_char_p
            out["blas_core"] = fn().decode()
            break
    out["numba_cpu"] = numba.config.CPU_NAME or "host"
    out["numba_svml"] = bool(numba.config.USING_SVML)
    return out
