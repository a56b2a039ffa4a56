"""Training's split, scaler and early stopping, pinned where test_lrmm.py leaves room."""

import dataclasses

import numpy as np
import pytest

from rmm_guardians.lrmm.train import TrainConfig, fit_minmax, split_by_config, train


def quiet(*a):
    pass


def test_minmax_scaler_by_hand_and_constant_features_pass_through():
    lo, scale = fit_minmax(np.array([[1.0, 5.0, -2.0], [3.0, 5.0, 2.0]]))
    assert lo.tolist() == [1.0, 5.0, -2.0] and scale.tolist() == [0.5, 1.0, 0.25]


def test_three_configurations_are_enough_for_a_split_and_two_are_not():
    ids = np.array([0, 0, 1, 1, 2, 2, 2])
    tr, va, te = split_by_config(ids, 0.15, 0.15, seed=0)
    assert sorted(len(set(ids[m])) for m in (tr, va, te)) == [1, 1, 1]
    assert not np.any((tr & va) | (tr & te) | (va & te)) and np.all(tr | va | te)
    with pytest.raises(ValueError, match="2 obstacle configuration.*at least 3"):
        split_by_config(np.array([0, 1, 1]), 0.15, 0.15, seed=0)


def test_early_stopping_stops_after_patience_epochs_without_improvement(small_dataset):
    ds, _ = small_dataset
    m = train(ds, TrainConfig(hidden=(8,), epochs=15, lr=0.05, patience=2, seed=3), log=quiet)
    t = m.meta["training"]
    hist = t["val_mse_history"]
    # replay the rule on the recorded validation losses: stop once 2 epochs in a row fail to beat the best
    best, stale, stop = np.inf, 0, None
    for i, v in enumerate(hist):
        best, stale = (v, 0) if v < best else (best, stale + 1)
        if stale >= 2:
            stop = i + 1
            break
    assert stop is not None and stop < 15  # the case stops early
    assert t["epochs_run"] == stop == len(hist)
    assert t["best_epoch"] == int(np.argmin(hist)) + 1 == t["selected_epoch"]
    assert m.meta["env_id"] == ds.meta["env_id"]


def test_float32_training_runs_in_float32(small_dataset):
    ds, _ = small_dataset
    m = train(ds, TrainConfig(hidden=(4,), epochs=1, dtype="float32", seed=0), log=quiet)
    assert (
        next(m.torch_net.parameters()).dtype.is_floating_point
        and str(next(m.torch_net.parameters()).dtype) == "torch.float32"
    )
    assert np.isfinite(m.meta["metrics"]["val"]["mae"])


def test_non_finite_labels_are_refused_naming_them(small_dataset):
    ds, _ = small_dataset
    bad = dataclasses.replace(ds, risk=np.where(np.arange(len(ds)) == 3, np.nan, ds.risk))
    with pytest.raises(ValueError, match="the dataset holds non-finite observations or labels"):
        train(bad, TrainConfig(epochs=1), log=quiet)
