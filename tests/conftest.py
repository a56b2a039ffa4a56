import pytest


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """A small real dataset (8 configurations x 24 samples, a cheap tree)."""
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    out = tmp_path_factory.mktemp("data") / "d4small"
    generate(DatagenConfig(configs=8, samples_per_config=24, branches=6, depth=2, configs_per_shard=4, seed=11),
             out, workers=1, progress=False)
    return load_dataset(out), out
