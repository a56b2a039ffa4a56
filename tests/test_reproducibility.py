"""Same seed, same bits on every machine.

* The fingerprint of ``benchmarks/check_behaviour.py`` (generated worlds, env rollouts with
  their info, risk labels, ``rmm-datagen`` datasets, HJ value functions and fixed-clock
  ``rmm-bench`` episodes of all three systems), computed at its quick size in a fresh
  interpreter under several machines' arithmetic: the BLAS kernel numpy's OpenBLAS uses
  (``OPENBLAS_CORETYPE`` Prescott, Haswell, SkylakeX where the CPU has AVX-512), the CPU numba
  compiles for (``NUMBA_CPU_NAME`` generic, or the host) and the SIMD loops numpy dispatches to
  (``NPY_DISABLE_CPU_FEATURES``).  Each must equal the committed record
  ``tests/data/fingerprint_quick.json`` when the installed numpy, numba, ... are the versions it
  was made with, and the portable setting's own fingerprint otherwise.  After a change that is
  meant to move results, record it again:
  ``python benchmarks/check_behaviour.py record tests/data/fingerprint_quick.json --size quick``.
* A static check that the code whose results a seed determines sends nothing to BLAS and calls
  none of numpy's CPU-dispatched transcendental functions (see :mod:`rmm_envs.portable`).
* The portable helpers themselves, against plain Python arithmetic.
"""

from __future__ import annotations

import ast
import functools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.check_behaviour import SECTIONS, arith_settings, compare, describe, run_under
from rmm_envs import portable

ROOT = Path(__file__).resolve().parent.parent
RECORD = ROOT / "tests" / "data" / "fingerprint_quick.json"
SETTINGS = arith_settings()


@functools.lru_cache(maxsize=None)
def _fingerprint(i: int) -> dict:
    return run_under(SETTINGS[i], "quick", timeout=900)


@pytest.mark.parametrize("i", range(len(SETTINGS)), ids=[describe(s).replace(" ", "") for s in SETTINGS])
def test_the_same_bits_under_each_machines_arithmetic(i):
    record = json.loads(RECORD.read_text())
    fp = _fingerprint(i)
    assert set(SECTIONS) <= set(fp), f"the fingerprint lacks sections {set(SECTIONS) - set(fp)}"
    if fp["versions"] == record["versions"]:
        ref, what = record, f"the committed record {RECORD.relative_to(ROOT)}"
    elif i == 0:
        pytest.skip(f"the record was made with {record['versions']}, this install has {fp['versions']}: "
                    "the other settings are compared with this one")
    else:
        ref, what = _fingerprint(0), f"the portable setting ({describe(SETTINGS[0])})"
    diffs = compare(ref, fp)
    assert not diffs, (f"under {describe(SETTINGS[i])} the fingerprint differs from {what} in {len(diffs)} field(s); "
                       f"first: {diffs[0]}")


def test_the_settings_cover_the_kernels_the_issue_names():
    kernels = {s["OPENBLAS_CORETYPE"] for s in arith_settings(set())}
    assert {"Prescott", "Haswell", None} <= kernels and "SkylakeX" not in kernels
    assert "SkylakeX" in {s["OPENBLAS_CORETYPE"] for s in arith_settings({"avx512f"})}
    assert {s["NUMBA_CPU_NAME"] for s in SETTINGS} == {"generic", None}
    portable_first = SETTINGS[0]
    assert portable_first["OPENBLAS_CORETYPE"] == "Prescott" and portable_first["NUMBA_CPU_NAME"] == "generic"


def test_compare_names_the_first_field_that_differs():
    a = {"worlds": {"r": "1"}, "bench": {"lrmm/0": {"outcome": "goal", "steps": 10}}}
    b = {"worlds": {"r": "1"}, "bench": {"lrmm/0": {"outcome": "collision", "steps": 10}}}
    assert compare(a, b) == ["bench: lrmm/0: outcome 'goal' -> 'collision'"]
    assert compare(a, a) == []


# ---------------------------------------------------------------------------- static check
# numpy calls whose result depends on the CPU: BLAS, or numpy's own SIMD code on some CPUs
_BLAS = {"dot", "inner", "vdot", "matmul", "tensordot", "outer"}
_LINALG = {"norm", "solve", "inv", "lstsq", "eig", "eigh", "svd", "det", "pinv", "cholesky", "qr", "multi_dot"}
_DISPATCHED = {"exp", "log", "expm1", "log1p", "arctan2", "arctan", "arcsin", "arccos", "tan", "tanh", "sinh", "cosh",
               "power", "cbrt", "exp2", "log2", "log10", "angle", "float_power"}
# where a machine-dependent result is harmless: drawing, torch training, perf scripts' own timing
_EXEMPT_FILES = {"rmm_envs/envs/_render.py", "guardians/lrmm/train.py", "rmm_envs/cli.py"}


def _compiled(fn: ast.AST) -> bool:
    """A function numba compiles: its numpy calls become C-library calls, the same everywhere."""
    decos = getattr(fn, "decorator_list", [])
    names = {ast.unparse(d).split("(")[0].split(".")[-1] for d in decos}
    return bool(names & {"njit", "jit", "vectorize", "guvectorize", "stencil"})


def machine_dependent_calls(path: Path) -> list[str]:
    tree = ast.parse(path.read_text())
    rel = path.relative_to(ROOT).as_posix()
    compiled_names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and _compiled(n)}
    # functions compiled by a call (``f = njit(cache=True)(f)``) count too
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and isinstance(node.value.func, ast.Call):
            if ast.unparse(node.value.func.func).split(".")[-1] in {"njit", "jit"}:
                compiled_names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    found = []

    def visit(node, in_compiled: bool):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            in_compiled = in_compiled or node.name in compiled_names
        if not in_compiled:
            if isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
                found.append(f"{rel}:{node.lineno}: '@' ({ast.unparse(node)[:60]})")
            if isinstance(node, ast.Call):
                f = ast.unparse(node.func)
                parts = f.split(".")
                if parts[0] in ("np", "numpy") and len(parts) == 2 and parts[1] in _BLAS | _DISPATCHED:
                    found.append(f"{rel}:{node.lineno}: {f}")
                elif f.endswith(".dot") and parts[0] not in ("np", "numpy", "portable"):
                    found.append(f"{rel}:{node.lineno}: {f}")
                elif parts[:2] in (["np", "linalg"], ["numpy", "linalg"]) and parts[-1] in _LINALG:
                    if not (parts[-1] == "norm" and any(k.arg == "axis" for k in node.keywords)):
                        found.append(f"{rel}:{node.lineno}: {f} (BLAS)")
        for child in ast.iter_child_nodes(node):
            visit(child, in_compiled)

    visit(tree, False)
    return found


def test_seeded_code_sends_nothing_to_blas_or_numpys_simd_transcendentals():
    files = sorted(p for pkg in ("rmm_envs", "guardians") for p in (ROOT / pkg).rglob("*.py"))
    found = [hit for p in files if p.relative_to(ROOT).as_posix() not in _EXEMPT_FILES for hit in machine_dependent_calls(p)]
    assert not found, ("machine-dependent arithmetic in seeded code (use rmm_envs.portable: dot, norm, norms, matvec, "
                       "arctan2, wrap_angle, or a numba kernel):\n" + "\n".join(found))


def test_the_static_check_finds_what_it_looks_for(tmp_path):
    src = ROOT / "rmm_envs" / "_probe_static_check.py"
    src.write_text("import numpy as np\nfrom numba import njit\n\n"
                   "def f(a, b):\n    return a @ b, np.dot(a, b), np.linalg.norm(a), np.exp(a), a.dot(b), np.linalg.norm(a, axis=1)\n\n"
                   "@njit(cache=False)\ndef g(a):\n    return np.exp(a)\n")
    try:
        hits = machine_dependent_calls(src)
    finally:
        src.unlink()
    assert [h.split(": ", 1)[1].split(" ")[0] for h in hits] == ["'@'", "np.dot", "np.linalg.norm", "np.exp", "a.dot"]


# ---------------------------------------------------------------------------- the helpers
_floats = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(st.lists(_floats, min_size=1, max_size=8))
def test_norm_is_the_square_root_of_the_squares_summed_left_to_right(xs):
    s = 0.0
    for x in xs:
        s += x * x
    assert portable.norm(np.array(xs)) == math.sqrt(s)
    assert portable.norms(np.array([xs, xs]))[1] == math.sqrt(s) or len(xs) >= 8  # numpy pairs from 8 terms on


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(_floats, _floats), min_size=1, max_size=7))
def test_dot_and_matvec_sum_left_to_right(pairs):
    a, b = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])
    s = 0.0
    for x, y in pairs:
        s += x * y
    assert portable.dot(a, b) == s
    assert portable.matvec(np.stack([a, b]), b)[0] == s
    assert portable.matvec(np.stack([np.stack([a, b])] * 2), np.stack([b, b]))[1, 0] == s  # stacked


@settings(max_examples=300, deadline=None)
@given(_floats, _floats)
def test_arctan2_is_the_c_librarys(y, x):
    assert portable.arctan2(np.array([y]), np.array([x]))[0] == math.atan2(y, x)
    assert portable.arctan2(y, x) == math.atan2(y, x)


@settings(max_examples=300, deadline=None)
@given(st.floats(-1e4, 1e4, allow_nan=False))
def test_wrap_angle_lands_in_minus_pi_to_pi_and_keeps_the_direction(t):
    w = float(portable.wrap_angle(t))
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(t), abs_tol=1e-9) and math.isclose(math.sin(w), math.sin(t), abs_tol=1e-9)
