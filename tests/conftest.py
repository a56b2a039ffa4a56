import fcntl

import pytest


def pytest_collection_modifyitems(config, items):
    """Tests marked ``heavy`` run first, the rest in their own order: with two workers
    (``make test``) a half-minute test started last keeps one core busy after the other has
    finished; started first, the short tests fill in around it.  ``heavy(seconds=N)`` orders them
    longest first (default 20)."""

    def order(item):
        mark = item.get_closest_marker("heavy")
        return (1, 0.0) if mark is None else (0, -float(mark.kwargs.get("seconds", 20)))

    items.sort(key=order)  # stable: the rest keep their order


@pytest.fixture(autouse=True, scope="session")
def _hj_cache(tmp_path_factory):
    """Keep HJ value functions solved by tests out of the user's cache."""
    import os

    os.environ["RMM_HJ_CACHE"] = str(tmp_path_factory.mktemp("hjcache"))


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """A small real dataset (8 configurations x 24 samples, a cheap tree)."""
    from rmm_envs.risk.datagen import DatagenConfig, generate, load_dataset

    out = tmp_path_factory.mktemp("data") / "d4small"
    generate(
        DatagenConfig(configs=8, samples_per_config=24, branches=6, depth=2, configs_per_shard=4, seed=11),
        out,
        workers=1,
        progress=False,
    )
    return load_dataset(out), out


@pytest.fixture(scope="session")
def maze_hj_cache(tmp_path_factory):
    """One value cache for the maze ``hj`` tests of a session (they share the corridor's value),
    or ``$RMM_TEST_HJ_CACHE`` when set: kept between sessions, so that ``make mutate``'s runs,
    one session per mutant, solve it once."""
    import os

    return os.environ.get("RMM_TEST_HJ_CACHE") or tmp_path_factory.mktemp("maze_hj")


@pytest.fixture(scope="session")
def once_per_run(tmp_path_factory, request):
    """``once_per_run(name, make)``: a directory that ``make(directory)`` filled once for the
    whole test run, whichever worker asked first; the others wait for it and share it.

    A module-scoped fixture is set up once per worker, and ``make test``'s two workers each take
    some of a module's tests: an expensive one (an HJ solve, a benchmark run in a fresh
    interpreter) was made twice.  The directory is under the run's own base temporary
    directory (shared by its xdist workers, fresh every run); a ``make`` that raises does not
    mark it made, and the next worker to ask starts it again in an empty directory."""
    import shutil

    base = tmp_path_factory.getbasetemp()
    # a local xdist worker's base is the run's own base + popen-gwN; elsewhere (no xdist, or a
    # remote worker) the base itself, which no other run shares
    shared = base.parent if hasattr(request.config, "workerinput") and base.name.startswith("popen-") else base

    def once(name: str, make):
        out = shared / f"once-{name}"
        with open(shared / f"once-{name}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)  # held until the file closes
            if not (out / ".made").exists():
                shutil.rmtree(out, ignore_errors=True)  # what a failed attempt left
                out.mkdir()
                make(out)
                (out / ".made").touch()
        return out

    return once
