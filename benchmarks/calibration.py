"""Moved: ``rmm-bench calibrate`` (:mod:`rmm_bench.calibration`).  This shim keeps
``python -m benchmarks.calibration`` and ``from benchmarks import calibration`` working in a clone."""

from __future__ import annotations

import sys

from rmm_bench.calibration import CALIBRATED, calibrate, cmd, main, reliability

__all__ = ["CALIBRATED", "calibrate", "cmd", "main", "reliability"]

if __name__ == "__main__":
    sys.exit(main())
