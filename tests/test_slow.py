"""Slow checks, not part of `make test`: run with `.venv/bin/python -m pytest -m slow`."""

import time

import numpy as np
import pytest

pytestmark = pytest.mark.slow


def test_paper_scale_dubins4d_dataset(tmp_path):
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    t0 = time.perf_counter()
    man = generate(DatagenConfig(configs=274, samples_per_config=128, seed=0), tmp_path / "d4", workers=2, progress=False)
    elapsed = time.perf_counter() - t0
    ds = load_dataset(tmp_path / "d4")
    assert man["n_rows"] == len(ds) == 35072
    assert np.unique(ds.config_id).size == 274
    assert 0.1 < ds.risk.mean() < 0.4
    print(f"35,072 labels in {elapsed:.1f} s")


def test_default_grid_hj_solve_is_consistent():
    from guardians.hj.dynamics import Dubins4DHJ
    from guardians.hj.guardian import default_grid, obstacle_target
    from guardians.hj.solver import solve_brt

    grid = default_grid()
    obstacles = np.array([[0.0, 0.0, 3.0]])
    V, info = solve_brt(grid, Dubins4DHJ(), obstacle_target(grid, obstacles), 4.0)
    assert V.dtype == np.float32 and V.shape == (64, 64, 32, 32)
    # heading straight at the obstacle at 2 m/s.  An independent check with the exact
    # propagator: from a gap of 4 m or more some constant control keeps clear for 4 s, so those
    # states must be safe (HJ may also use time-varying controls, so its safe set is larger);
    # from 0.5-1 m nothing escapes (every constant control collides, and braking needs 4 m).
    from rmm_envs.systems.dubins4d import Dubins4D

    dyn = Dubins4D()
    controls = np.array([[u1, u2] for u1 in np.linspace(-0.25, 0.25, 11) for u2 in np.linspace(-0.5, 0.5, 11)])
    for gap, unsafe in ((0.5, True), (1.0, True), (4.0, False), (5.0, False), (6.0, False)):
        s = np.array([-3.0 - gap, 0.0, 0.0, 2.0])
        paths = dyn.propagate(np.repeat(s[None], len(controls), 0), controls, 4.0, 400)
        clearance = (np.hypot(paths[..., 0], paths[..., 1]) - 3.0).min(axis=1).max()
        assert (clearance <= 0) == unsafe, (gap, clearance)
        assert (grid.interp(V, s) <= 0) == unsafe, gap
    # heading away is safe even close by
    assert grid.interp(V, np.array([-3.5, 0.0, np.pi - 1e-6, 2.0])) > 0
