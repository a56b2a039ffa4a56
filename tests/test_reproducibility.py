"""Same seed, same bits on every machine.

* The fingerprint of ``benchmarks/check_behaviour.py`` (generated worlds, env rollouts with
  their info, risk labels, ``rmm-datagen`` datasets, HJ value functions and fixed-clock
  ``rmm-bench`` episodes of all three systems), computed at its quick size in a fresh
  interpreter under several machines' arithmetic (two in the default suite, the rest with
  ``-m slow``, see ``CASES``): the BLAS kernel numpy's OpenBLAS uses
  (``OPENBLAS_CORETYPE`` Prescott, Haswell, SkylakeX where the CPU has AVX-512), the CPU numba
  compiles for (``NUMBA_CPU_NAME`` generic, or the host) and the SIMD loops numpy dispatches to
  (``NPY_DISABLE_CPU_FEATURES``).  Each must equal the committed record
  ``tests/data/fingerprint_quick.json`` when the installed numpy, numba, ... are the versions it
  was made with, and the portable setting's own fingerprint otherwise.  After a change that is
  meant to move results, record it again:
  ``python -m benchmarks.check_behaviour record tests/data/fingerprint_quick.json --size quick``.
* A static check that the code whose results a seed determines sends nothing to BLAS and calls
  none of numpy's CPU-dispatched transcendental functions (see :mod:`rmm_envs.machine_independent`).
* The portable helpers themselves, against plain Python arithmetic.
"""

from __future__ import annotations

import ast
import functools
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchmarks.arith import applied, arith_settings, describe, run_under
from benchmarks.check_behaviour import SECTIONS, compare
from rmm_envs import machine_independent as portable

ROOT = Path(__file__).resolve().parent.parent
RECORD = ROOT / "tests" / "data" / "fingerprint_quick.json"
SETTINGS = arith_settings()


#: The default suite's two cases: the oldest BLAS kernel with numpy's SIMD dispatch below AVX2
#: (everything that reaches BLAS or numpy's dispatched loops on an old machine), and the host's
#: own arithmetic.  Both compile numba for the host, whose kernels the suite has cached by the
#: time they run.  Numba's target CPU (``NUMBA_CPU_NAME=generic``) and the kernels in between
#: are the ``-m slow`` cases below (each a fresh interpreter; a generic CPU compiles every
#: kernel again, about 50 s of CPU on a fresh clone); the static check further down refuses
#: ``fastmath``, the one way numba code comes to depend on the CPU it was compiled for.
OLD_KERNEL = {**SETTINGS[0], "NUMBA_CPU_NAME": None}
HOST = SETTINGS[-1]
CASES = [
    pytest.param(OLD_KERNEL, id="old-kernel:" + describe(OLD_KERNEL).replace(" ", "")),
    pytest.param(HOST, id="host:" + describe(HOST).replace(" ", "")),
]
CASES += [pytest.param(s, id=describe(s).replace(" ", ""), marks=pytest.mark.slow) for s in SETTINGS[:-1]]


@functools.cache
def _fingerprint_of(key: tuple) -> dict:
    return run_under(dict(key), "quick", timeout=900)


def _fingerprint(setting: dict) -> dict:
    return _fingerprint_of(tuple(sorted(setting.items())))


@pytest.mark.parametrize("setting", CASES)
def test_the_same_bits_under_each_machines_arithmetic(setting):
    record = json.loads(RECORD.read_text())
    fp = _fingerprint(setting)
    assert set(SECTIONS) <= set(fp) and set(SECTIONS) <= set(record), (
        f"sections missing: fingerprint {set(SECTIONS) - set(fp)}, record {set(SECTIONS) - set(record)}"
    )
    _check_applied(setting, fp["applied"])
    if fp["versions"] == record["versions"]:
        ref, what = record, f"the committed record {RECORD.relative_to(ROOT)}"
    elif setting == HOST:
        pytest.skip(
            f"the record was made with {record['versions']}, this install has {fp['versions']}: "
            "the other settings are compared with the host's own"
        )
    else:
        ref, what = _fingerprint(HOST), f"the host's own arithmetic ({describe(HOST)})"
    diffs = compare(ref, fp)
    assert not diffs, (
        f"under {describe(setting)} the fingerprint differs from {what} in {len(diffs)} field(s); first: {diffs[0]}"
    )


def _check_applied(setting: dict, got: dict) -> None:
    """The setting really changed the arithmetic (a variable that a numpy, numba or BLAS build
    ignores would make the comparison vacuous)."""
    assert got["numba_cpu"] == (setting["NUMBA_CPU_NAME"] or "host"), got
    disabled = (setting["NPY_DISABLE_CPU_FEATURES"] or "").split()
    for func in ("numpy_exp", "numpy_arctan2"):
        assert not any(got[func].startswith(f) for f in disabled), f"{func} still runs {got[func]} under {setting}"
    here = applied()["blas_core"]  # this process's kernel: the machine's default unless chosen by hand
    want = setting["OPENBLAS_CORETYPE"]
    if want and here and got["blas_core"] and want.lower() != here.lower() and not os.environ.get("OPENBLAS_CORETYPE"):
        assert got["blas_core"] != here, f"OPENBLAS_CORETYPE={want} did not change the kernel ({here})"


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
_BLAS = {
    "dot",
    "inner",
    "vdot",
    "matmul",
    "tensordot",
    "outer",
    "convolve",
    "correlate",
    "cov",
    "corrcoef",
    "vecdot",
    "matvec",
    "vecmat",
    "kron",
}
_DISPATCHED = {
    "exp",
    "log",
    "expm1",
    "log1p",
    "arctan2",
    "arctan",
    "arcsin",
    "arccos",
    "tan",
    "tanh",
    "sinh",
    "cosh",
    "arcsinh",
    "arccosh",
    "arctanh",
    "power",
    "float_power",
    "cbrt",
    "exp2",
    "log2",
    "log10",
    "angle",
    "logaddexp",
    "logaddexp2",
}
# np.argpartition / np.partition, and argsort unless stable: the tie order is the SIMD sort code's
_EXACT_POWERS = {0, 1, 2, -1, 0.5}  # numpy's fast paths: a product, a square, a reciprocal or sqrt
# where a machine-dependent result is harmless: drawing figures
_EXEMPT_FILES = {"rmm_envs/envs/_render.py", "benchmarks/bench/paper_figures.py"}
#: a line may say why a flagged form is exact there, e.g. an integer power: ``# exact: integers``
_PRAGMA = "# exact:"


def _aliases(tree: ast.AST) -> dict[str, str]:
    """Local name -> dotted numpy name, from the module's imports (``np`` -> ``numpy``,
    ``la`` -> ``numpy.linalg``, ``exp`` -> ``numpy.exp``)."""
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "numpy":
                    out[a.asname or a.name.split(".")[0]] = a.name if a.asname else "numpy"
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] == "numpy":
            for a in node.names:
                out[a.asname or a.name] = f"{node.module}.{a.name}"
    return out


def _compiled(fn: ast.AST) -> bool:
    """A function numba compiles: its transcendental calls become C-library calls, the same
    everywhere (but ``@``, ``np.dot`` and ``np.linalg`` still reach BLAS there)."""
    names = {ast.unparse(d).split("(")[0].split(".")[-1] for d in getattr(fn, "decorator_list", [])}
    return bool(names & {"njit", "jit", "vectorize", "guvectorize", "stencil"})


def machine_dependent_calls(path: Path) -> list[str]:
    text = path.read_text()
    lines = text.splitlines()
    tree = ast.parse(text)
    try:
        rel = path.relative_to(ROOT).as_posix()
    except ValueError:
        rel = path.name
    alias = _aliases(tree)
    compiled_names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and _compiled(n)}
    for node in ast.walk(tree):  # compiled by a call: ``f = njit(cache=True)(f)``
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call) and isinstance(node.value.func, ast.Call):
            if ast.unparse(node.value.func.func).split(".")[-1] in {"njit", "jit"}:
                compiled_names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    found = []

    def flag(node, what):
        line = lines[node.lineno - 1] if node.lineno <= len(lines) else ""
        if _PRAGMA not in line:
            found.append(f"{rel}:{node.lineno}: {what}")

    def numpy_name(func) -> str:
        parts = ast.unparse(func).split(".")
        head = alias.get(parts[0])
        return ".".join([head] + parts[1:]) if head else ""

    def visit(node, in_compiled: bool):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            in_compiled = in_compiled or node.name in compiled_names
        if isinstance(node, ast.Call) and "fastmath" in {k.arg for k in node.keywords}:
            flag(node, "fastmath (FMA contraction and reordering differ by CPU)")
        if (
            isinstance(node, ast.BinOp)
            and isinstance(node.op, ast.MatMult)
            or isinstance(node, ast.AugAssign)
            and isinstance(node.op, ast.MatMult)
        ):
            flag(node, f"'@' ({ast.unparse(node)[:60]})")
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow) and not in_compiled:
            e = node.right
            v = (
                e.value
                if isinstance(e, ast.Constant)
                else (
                    -e.operand.value
                    if isinstance(e, ast.UnaryOp) and isinstance(e.op, ast.USub) and isinstance(e.operand, ast.Constant)
                    else None
                )
            )
            base = node.left.operand if isinstance(node.left, ast.UnaryOp) else node.left
            int_base = isinstance(base, ast.Constant) and isinstance(base.value, int)  # 2 ** 20, (-1) ** j: integers
            if v not in _EXACT_POWERS and not int_base:
                flag(node, f"'**' ({ast.unparse(node)[:60]}: np.power on arrays)")
        if isinstance(node, ast.Call):
            name = numpy_name(node.func)
            parts = name.split(".")
            method = ast.unparse(node.func).split(".")[-1] if isinstance(node.func, ast.Attribute) else ""
            kinds = {k.arg: ast.unparse(k.value) for k in node.keywords}
            if parts[:1] == ["numpy"] and len(parts) == 2 and parts[1] in _BLAS:
                flag(node, f"{name} (BLAS)")
            elif parts[:2] == ["numpy", "linalg"]:
                exact_norm = (
                    parts[-1] == "norm"
                    and "axis" in kinds
                    and kinds.get("ord", "None") in ("None", "2")
                    and not in_compiled
                )
                if not exact_norm:
                    flag(node, f"{name} (BLAS or LAPACK)")
            elif parts[:1] == ["numpy"] and parts[-1] == "einsum" and kinds.get("optimize", "False") != "False":
                flag(node, f"{name}(optimize=...) (BLAS)")
            elif parts[:1] == ["numpy"] and len(parts) == 2 and parts[1] in _DISPATCHED and not in_compiled:
                flag(node, f"{name} (numpy's SIMD code on some CPUs)")
            elif not name and method == "dot" and not ast.unparse(node.func).startswith("portable."):
                flag(node, f"{ast.unparse(node.func)} (BLAS)")
            elif (
                parts[-1:] == ["argpartition"]
                or method == "argpartition"
                or parts[-1:] == ["partition"]
                or (
                    (parts[-1:] == ["argsort"] or method == "argsort")
                    and kinds.get("kind", "None").strip("'\"") not in ("stable", "mergesort")
                )
            ):
                flag(node, f"{ast.unparse(node.func)} (tie order depends on the CPU's sort code)")
        for child in ast.iter_child_nodes(node):
            visit(child, in_compiled)

    visit(tree, False)
    return found


def test_seeded_code_sends_nothing_to_blas_or_numpys_simd_transcendentals():
    files = sorted(p for pkg in ("rmm_envs", "guardians", "benchmarks/bench") for p in (ROOT / pkg).rglob("*.py"))
    found = [
        hit for p in files if p.relative_to(ROOT).as_posix() not in _EXEMPT_FILES for hit in machine_dependent_calls(p)
    ]
    assert not found, (
        "machine-dependent arithmetic in seeded code (use rmm_envs.machine_independent: dot, norm, norms, matvec, "
        f"arctan2, wrap_angle, a numba kernel, or say why it is exact with '{_PRAGMA} ...'):\n" + "\n".join(found)
    )


def test_the_static_check_finds_what_it_looks_for(tmp_path):
    src = tmp_path / "probe.py"  # not in the package: other tests walk it
    src.write_text(
        "import numpy as np\nimport numpy.linalg as la\nfrom numpy import exp as e\nfrom numba import njit\n\n"
        "def f(a, b):\n    a @= b\n"
        "    return (a @ b, np.dot(a, b), np.linalg.norm(a), np.exp(a), a.dot(b), np.linalg.norm(a, axis=1),\n"
        "            la.solve(a, b), e(a), a ** 3, a ** 2, a ** 0.5, np.argsort(a), np.argsort(a, kind='stable'),\n"
        "            np.convolve(a, b), np.arcsinh(a), np.einsum('ij,j', a, b, optimize=True),\n"
        "            a ** 3)  # exact: a pragma names why a flagged form is exact on its line\n\n"
        "@njit(cache=False)\ndef g(a):\n    return np.exp(a), a ** 3, a @ a\n\n"
        "@njit(cache=True, fastmath=True)\ndef h(a):\n    return a * a + a\n"
    )
    hits = [h.split(": ", 1)[1].split(" ")[0] for h in machine_dependent_calls(src)]
    assert hits == [
        "'@'",
        "'@'",
        "numpy.dot",
        "numpy.linalg.norm",
        "numpy.exp",
        "a.dot",
        "numpy.linalg.solve",
        "numpy.exp",
        "'**'",
        "np.argsort",
        "numpy.convolve",
        "numpy.arcsinh",
        "numpy.einsum(optimize=...)",
        "'@'",
        "fastmath",
    ], hits


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
