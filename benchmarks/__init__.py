"""Development tools of the repository: performance measurements (``perf_*.py``), behaviour
fingerprints and checks.  Not part of the installed package (the harness is :mod:`rmm_bench`);
run them from the repository root as modules, e.g. ``python -m benchmarks.perf_env``.
"""
