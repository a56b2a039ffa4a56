"""Slow checks, not part of `make test`: run with `.venv/bin/python -m pytest -m slow`."""

import time

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_paper_scale_dubins4d_dataset(tmp_path):
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    t0 = time.perf_counter()
    man = generate(
        DatagenConfig(configs=274, samples_per_config=128, seed=0), tmp_path / "d4", workers=2, progress=False
    )
    elapsed = time.perf_counter() - t0
    ds = load_dataset(tmp_path / "d4")
    assert man["n_rows"] == len(ds) == 35072
    assert np.unique(ds.config_id).size == 274
    assert 0.1 < ds.risk.mean() < 0.4
    print(f"35,072 labels in {elapsed:.1f} s")


# the default-grid HJ check that was here runs by default now:
# tests/test_hj.py::test_default_grid_value_against_the_exact_propagator
