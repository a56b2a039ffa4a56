import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import rmm_envs  # noqa: F401
from guardians.lrmm.guardian import LRMMGuardian
from guardians.lrmm.model import LRMMModel, default_model_path, load_model
from guardians.lrmm.train import TrainConfig, main as train_main, split_by_config, train


def quiet(*a):
    pass


@pytest.fixture(scope="module")
def trained(small_dataset):
    ds, _ = small_dataset
    return train(ds, TrainConfig(epochs=3, seed=1), log=quiet)


def test_split_never_shares_a_configuration(small_dataset):
    ds, _ = small_dataset
    tr, va, te = split_by_config(ds.config_id, 0.2, 0.2, seed=0)
    sets = [set(ds.config_id[m].tolist()) for m in (tr, va, te)]
    assert not (sets[0] & sets[1]) and not (sets[0] & sets[2]) and not (sets[1] & sets[2])
    assert (tr | va | te).all() and all(sets)


def test_scaler_is_fitted_on_the_training_split_only(small_dataset, trained):
    ds, _ = small_dataset
    tr, va, te = split_by_config(ds.config_id, 0.15, 0.15, seed=1)
    obs = ds.obs.astype(float)
    np.testing.assert_array_equal(trained.scaler_min, obs[tr].min(axis=0))
    rng = obs[tr].max(axis=0) - obs[tr].min(axis=0)
    np.testing.assert_allclose(trained.scaler_scale, np.where(rng > 0, 1 / np.where(rng > 0, rng, 1), 1))
    assert not np.array_equal(obs[tr].min(axis=0), obs.min(axis=0)) or not np.array_equal(obs[tr].max(axis=0), obs.max(axis=0))
    split = trained.meta["split"]
    assert set(split["test_configs"]).isdisjoint(split["train_configs"])


def test_numpy_inference_equals_torch(small_dataset, trained):
    import torch

    ds, _ = small_dataset
    x = ds.obs.astype(float)
    xs = (x - trained.scaler_min) * trained.scaler_scale
    with torch.no_grad():
        ref = trained.torch_net(torch.as_tensor(xs, dtype=torch.float64)).numpy()[:, 0]
    np.testing.assert_allclose(trained.predict(x), ref, atol=1e-6, rtol=0)
    assert trained.predict(x[0]) == pytest.approx(ref[0], abs=1e-6)


def test_save_load_round_trip_is_bit_exact(tmp_path, small_dataset, trained):
    p = trained.save(tmp_path / "m.npz")
    m = LRMMModel.load(p, env_id="Dubins4DCircles-v0", obs_dim=17)
    for (Wa, ba), (Wb, bb) in zip(trained.weights, m.weights):
        np.testing.assert_array_equal(Wa, Wb)
        assert (ba is None and bb is None) or np.array_equal(ba, bb)
    x = small_dataset[0].obs
    np.testing.assert_array_equal(trained.predict(x), m.predict(x))
    for key in ("env_id", "labeller", "data_sha256", "metrics", "features", "hidden"):
        assert m.meta[key] == trained.meta[key]
    assert m.meta["data_sha256"] == small_dataset[0].sha256
    assert set(m.meta["metrics"]) == {"train", "val", "test"}


def test_training_is_deterministic(small_dataset):
    ds, _ = small_dataset
    a = train(ds, TrainConfig(epochs=2, seed=5), log=quiet)
    b = train(ds, TrainConfig(epochs=2, seed=5), log=quiet)
    c = train(ds, TrainConfig(epochs=2, seed=6), log=quiet)
    for (Wa, _), (Wb, _) in zip(a.weights, b.weights):
        np.testing.assert_array_equal(Wa, Wb)
    assert not np.array_equal(a.weights[0][0], c.weights[0][0])


def test_configurable_architecture_and_features(small_dataset):
    ds, _ = small_dataset
    m = train(ds, TrainConfig(hidden=(16, 8), activation="tanh", output_bias=True, epochs=1, features=[4, 5, 6]), log=quiet)
    assert [W.shape for W, _ in m.weights] == [(16, 3), (8, 16), (1, 8)]
    assert m.weights[-1][1] is not None
    assert 0 < m.predict(ds.obs[0]) < 1


def test_training_refuses_empty_and_single_configuration(small_dataset):
    ds, _ = small_dataset
    one = dataclasses.replace(ds, obs=ds.obs[:24], state=ds.state[:24], risk=ds.risk[:24], config_id=ds.config_id[:24])
    with pytest.raises(ValueError, match="configuration"):
        train(one, TrainConfig(epochs=1), log=quiet)
    empty = dataclasses.replace(ds, obs=ds.obs[:0], risk=ds.risk[:0], config_id=ds.config_id[:0])
    with pytest.raises(ValueError, match="empty"):
        train(empty, TrainConfig(epochs=1), log=quiet)


@pytest.mark.parametrize("kw, match", [({"hidden": ()}, "hidden"), ({"epochs": 0}, "epochs"), ({"lr": 0}, "lr"),
                                       ({"val_frac": 0.6, "test_frac": 0.5}, "val_frac"), ({"activation": "gelu"}, "activation")])
def test_bad_training_config(kw, match):
    with pytest.raises(ValueError, match=match):
        TrainConfig(**kw)


def test_rmm_train_cli(tmp_path, small_dataset, capsys):
    _, path = small_dataset
    out = tmp_path / "cli.npz"
    assert train_main(["--data", str(path), "--out", str(out), "--epochs", "2", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "test" in text and "MAE" in text
    m = load_model(out)
    assert m.meta["training"]["command"].startswith("rmm-train")
    assert train_main(["--data", str(tmp_path / "nothing"), "--out", str(out)]) == 2
    assert "metadata.json" in capsys.readouterr().err


# ----------------------------------------------------------------------------- bad model files
def test_bad_model_files(tmp_path, trained):
    p = trained.save(tmp_path / "good.npz")
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        LRMMModel.load(tmp_path / "missing.npz")
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(p.read_bytes()[:200])
    with pytest.raises(ValueError, match="trunc.npz"):
        LRMMModel.load(trunc)
    with pytest.raises(ValueError, match="trained for env"):
        LRMMModel.load(p, env_id="QuadrotorRoom-v0")
    with pytest.raises(ValueError, match="observations of 17"):
        LRMMModel.load(p, obs_dim=16)
    # flip weights but keep the metadata: checksum mismatch
    with np.load(p, allow_pickle=False) as z:
        arrs = {k: z[k] for k in z.files}
    arrs["W0"] = arrs["W0"] + 1e-3
    bad = tmp_path / "tampered.npz"
    np.savez(bad, **arrs)
    with pytest.raises(ValueError, match="checksum"):
        LRMMModel.load(bad)
    np.savez(tmp_path / "nometa.npz", W0=np.zeros(3))
    with pytest.raises(ValueError, match="meta"):
        LRMMModel.load(tmp_path / "nometa.npz")


def test_predict_rejects_bad_observations(trained):
    with pytest.raises(ValueError, match="shape"):
        trained.predict(np.zeros(16))
    with pytest.raises(ValueError, match="NaN"):
        trained.predict(np.full(17, np.nan))


# ----------------------------------------------------------------------------- the guardian
def forward_ray_model(obs_dim=17):
    """A hand-made model: risk = sigmoid(20 * sigmoid(-2 (ray0 - 2))) - ... i.e. high when the forward ray is short."""
    W0 = np.zeros((1, obs_dim))
    W0[0, 5] = -4.0
    b0 = np.array([8.0])  # hidden = sigmoid(8 - 4 ray0): ~1 when ray0 < 1.5, ~0 when ray0 > 2.5
    W1 = np.array([[10.0]])
    b1 = np.array([-5.0])  # risk = sigmoid(10 h - 5): ~0.99 or ~0.007
    meta = {"env_id": "Dubins4DCircles-v0", "obs_dim": obs_dim, "features": list(range(obs_dim)), "hidden": [1],
            "activation": "sigmoid", "output_bias": True}
    return LRMMModel([(W0, b0), (W1, b1)], np.zeros(obs_dim), np.ones(obs_dim), meta)


def obs_with(ray0, left, right):
    o = np.zeros(17)
    o[5:] = 10.0
    o[5], o[6], o[16] = ray0, left, right
    return o


def test_lrmm_takes_control_above_threshold_and_turns_to_the_open_side():
    g = LRMMGuardian(forward_ray_model())
    g.reset(seed=0, observation_space=gym.spaces.Box(-np.inf, np.inf, (17,)))
    a = g.act(obs_with(1.0, left=8.0, right=2.0), {})
    assert g.last_risk > 0.85
    assert a["active_ctrl"] == 1 and a["accel_ctrl"][0] == -0.5 and a["turnrate_ctrl"][0] == 0.25
    a = g.act(obs_with(1.0, left=2.0, right=8.0), {})
    assert a["turnrate_ctrl"][0] == -0.25
    a = g.act(obs_with(1.0, left=5.0, right=5.0), {})
    assert a["active_ctrl"] == 1 and a["turnrate_ctrl"][0] == 0.0
    a = g.act(obs_with(9.0, left=8.0, right=2.0), {})  # clear road: control returns
    assert a["active_ctrl"] == 0


def test_lrmm_hysteresis_holds_control_while_the_average_is_high():
    g = LRMMGuardian(forward_ray_model(), hysteresis=True, window=8)
    g.reset(seed=0)
    for _ in range(8):
        g.act(obs_with(1.0, 8, 2), {})
    # risk drops to ~0.007 but the 8-sample mean stays above 0.85 for one more step
    acts = [g.act(obs_with(9.0, 8, 2), {})["active_ctrl"] for _ in range(4)]
    assert acts[0] == 1 and acts[-1] == 0
    plain = LRMMGuardian(forward_ray_model())
    plain.reset(seed=0)
    plain.act(obs_with(1.0, 8, 2), {})
    assert plain.act(obs_with(9.0, 8, 2), {})["active_ctrl"] == 0


def test_lrmm_guardian_bad_input():
    g = LRMMGuardian(forward_ray_model())
    with pytest.raises(ValueError, match="shape"):
        g.reset(seed=0, observation_space=gym.spaces.Box(-1, 1, (16,)))
    g.reset(seed=0)
    with pytest.raises(ValueError, match="NaN"):
        g.act(np.full(17, np.nan), {})
    with pytest.raises(ValueError, match="threshold"):
        LRMMGuardian(forward_ray_model(), threshold=2.0)
    with pytest.raises(FileNotFoundError):
        LRMMGuardian("/nonexistent/model.npz")


def test_shipped_model_loads_and_is_documented():
    m = load_model()
    assert default_model_path().exists()
    assert m.env_id == "Dubins4DCircles-v0" and m.obs_dim == 17
    assert m.meta["data"]["n_rows"] >= 35072 and m.meta["data"]["configs"] >= 274
    assert m.meta["metrics"]["test"]["mae"] <= 0.030
    assert m.meta["labeller"]["branches"] == 32 and m.meta["labeller"]["depth"] == 2
