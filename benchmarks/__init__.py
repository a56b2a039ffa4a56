"""Benchmark harness (rmm-bench) and performance measurements."""
