"""rmm_envs: environments, risk labelling and datasets for learned risk metric maps.

Importing the package registers the Gymnasium environments of its systems, all read from one
table, :data:`rmm_envs.catalog.SYSTEMS` (listed in docs/environments/index.md): per system
``<System>-v0`` (plain control), ``<System>Guarded-v0`` (a built-in driver a guardian may
override, blocking, fixed step) and ``<System>Parallel-v0`` (the same, non-blocking: the
guardian's compute time passes), for Dubins4D among circles and on maps of your own, the
Dubins3D maze car, the PyBullet quadrotor, and two simulators the project did not write
(Gymnasium's CartPole and MuJoCo InvertedPendulum, :mod:`rmm_envs.systems.cartpole.guarded`).
``gym.make_vec("Dubins4DGuarded-v0", num_envs=N)`` is a native numpy vector env.  Ids renamed to this scheme stay registered and
warn (:data:`rmm_envs.catalog.RENAMED`).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

from rmm_envs import catalog

try:
    __version__ = version("rmm-envs")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

#: The envs offering the parallel-autonomy contract (a built-in driver and a guardian action):
#: every system's ``Guarded`` and ``Parallel`` env (:data:`rmm_envs.catalog.SYSTEMS`).
GUARDIAN_ENV_IDS = catalog.guardian_env_ids()
#: Every env id this package registers (old ids of renamed envs, :data:`rmm_envs.catalog.RENAMED`, aside).
ENV_IDS = catalog.env_ids()

catalog.register()

__all__ = ["ENV_IDS", "GUARDIAN_ENV_IDS", "__version__"]
