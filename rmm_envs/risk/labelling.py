"""Algorithm 2 for a block of obstacle configurations: :class:`DatagenConfig`, the env (any
registered env that follows :class:`rmm_envs.risk.LabelledEnv`, or one a risk adapter of
:mod:`rmm_envs.adapters` serves), :func:`label_configs` and the metadata of a dataset.  The env
is reached through the protocol only, so a new labelled env needs no change here.

For an adapted env (``CartPole-v1``, the MuJoCo envs, ...) a "configuration" is one seeded
``reset`` of the env and its ``samples_per_config`` states come from the adapter's state
sampler (documented per adapter); ``horizon=None`` takes the adapter's default ``t`` (2 s for
the package's own envs) and ``failure="module:callable"`` names a failure test
``failure(states) -> (N,) bool`` (required for ``Pendulum-v1``), imported in every worker.
"""

from __future__ import annotations

import json
import os
import sysconfig
import time
import traceback
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import pyarrow as pa

import rmm_envs  # the package's own envs register on import
from rmm_envs.adapters import AdaptedEnv, adapt
from rmm_envs.defaults import DEFAULT_LABELLED_ENV
from rmm_envs.disturbances import parse_disturbances
from rmm_envs.disturbances.realisation import Realisation
from rmm_envs.disturbances.rows import observation_rows
from rmm_envs.env_plugins import describe_env_error, load_env_plugins, resolve_env_id
from rmm_envs.risk.dataset import FORMAT, FORMAT_VERSION
from rmm_envs.risk.estimator import RiskEstimator, validate_tree_params
from rmm_envs.risk.protocol import check_labelled_env
from rmm_envs.user_modules import UserModuleError, import_user_module

__all__ = ["DatagenConfig", "LabellingError", "config_seeds", "dataset_metadata", "label_configs", "labelled_env"]


class LabellingError(RuntimeError):
    """An exception raised by the env (its hooks, its simulator or its driver) while a dataset is
    made; its message is one line naming the env, what was being done, the exception's type and
    message, and where it was raised (see :func:`env_failure`)."""


def _raised_at(e: BaseException) -> str:
    """``path:line in function`` of the innermost frame of ``e``'s traceback outside the standard
    library and the installed packages (the code of the env, its simulator or driver), else of the
    innermost frame; ``""`` without a traceback."""
    frames = traceback.extract_tb(e.__traceback__)
    if not frames:
        return ""
    libs = tuple(
        os.path.realpath(p) + os.sep
        for p in {sysconfig.get_path(k) for k in ("stdlib", "platstdlib", "purelib", "platlib")}
        if p
    )
    ours = [f for f in frames if not os.path.realpath(f.filename).startswith(libs) and not f.filename.startswith("<")]
    frame = (ours or frames)[-1]
    path = frame.filename
    try:
        rel = os.path.relpath(path)
        path = rel if not rel.startswith(os.pardir) else path
    except ValueError:  # another drive (Windows)
        pass
    return f"{path}:{frame.lineno} in {frame.name}"


def env_failure(e: BaseException, env_id: str, during: str) -> LabellingError:
    """The one-line :class:`LabellingError` of ``e``, raised by the env ``env_id`` while ``during``:
    ``"--env <id>: <during> raised <Type>: <message> (at <path:line in function>)"``."""
    message = " ".join(line.strip() for line in str(e).splitlines() if line.strip()) or "(no message)"
    at = _raised_at(e)
    return LabellingError(
        f"--env {env_id}: {during} raised {type(e).__name__}: {message}" + (f" (at {at})" if at else "")
    )


@dataclass
class DatagenConfig:
    env_id: str = DEFAULT_LABELLED_ENV
    configs: int = 274
    samples_per_config: int = 128
    seed: int = 0
    branches: int = 32
    depth: int = 2
    horizon: float | None = None  # None: 2 s for the package's envs, the adapter's default for an adapted env
    n_steps: int = 8
    metric: str = "expected"
    alpha: float | None = None
    leaf: str = "zero"
    configs_per_shard: int = 8
    env_kwargs: dict = field(default_factory=dict)
    candidates: list | None = None  # action-conditioned labels: controls held for candidate_hold s
    candidate_hold: float = 1.0
    failure: str | None = None  # "module:callable", failure(states) -> (N,) bool for an adapted env

    def validate(self) -> None:
        # a module:Id or an entry point's env registers here (and in each worker, which builds its env from env_id);
        # an id that cannot is EnvUnavailable, a ValueError naming the id, the cause and the nearest registered id
        resolve_env_id(self.env_id)
        if self.failure is not None and not (
            isinstance(self.failure, str) and self.failure.count(":") == 1 and all(self.failure.split(":"))
        ):
            raise bad_failure(self.failure, "not of the form module:callable")
        for name in ("configs", "samples_per_config", "configs_per_shard"):
            v = getattr(self, name)
            if not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"seed (--seed) must be an integer >= 0, got {self.seed!r}")
        validate_tree_params(**self.estimator_params())
        for d in parse_disturbances((self.env_kwargs or {}).get("disturbances")):
            if d.target != "obs":
                raise ValueError(
                    f"disturbance {d}: a dataset takes sensor disturbances (obs-noise, obs-bias, ray-dropout) on its "
                    "observations; its labels are the risk under the nominal model (the estimator does not simulate "
                    f"{d.kind})"
                )
        if self.candidates is not None:
            c = np.asarray(self.candidates, dtype=float)
            if c.ndim != 2 or c.shape[0] < 1 or not np.all(np.isfinite(c)):
                raise ValueError(f"candidates must be a non-empty list of finite controls, got {self.candidates!r}")
            if not (np.isfinite(self.candidate_hold) and self.candidate_hold > 0):
                raise ValueError(f"candidate_hold must be a finite number of seconds > 0, got {self.candidate_hold!r}")

    @property
    def n_shards(self) -> int:
        return -(-self.configs // self.configs_per_shard)

    def shard_configs(self, shard: int) -> range:
        lo = shard * self.configs_per_shard
        return range(lo, min(self.configs, lo + self.configs_per_shard))

    def resolved_horizon(self) -> float:
        """``horizon``, or the env's default when it is ``None`` (see the module docstring)."""
        if self.horizon is not None:
            return self.horizon
        env = labelled_env(self)
        # an env built on an adapted simulator (rmm_envs.envs.any_env) states its adapter's default
        return env.scene.default_horizon if isinstance(env, AdaptedEnv) else getattr(env, "default_horizon", 2.0)

    def estimator_params(self) -> dict:
        return {
            "branches": self.branches,
            "depth": self.depth,
            "horizon": self.resolved_horizon(),
            "n_steps": self.n_steps,
            "metric": self.metric,
            "alpha": self.alpha,
            "leaf": self.leaf,
        }


_ENV_CACHE: dict = {}  # one env per (id, arguments) and process, reused by every configuration (reset re-seeds it)


def bad_failure(spec, why: str) -> ValueError:
    """The one refusal of a bad ``failure`` (``--failure``): the value, what was expected and why."""
    return ValueError(
        f"failure (--failure) must be 'module:callable' naming a function failure(states) -> (N,) bool, "
        f"got {spec!r}: {why}"
    )


def load_failure(spec: str | None):
    """The callable ``"module:callable"`` names (``None`` for ``None``); ``ValueError``
    (:func:`bad_failure`) naming what cannot be imported."""
    if spec is None:
        return None
    module, _, attr = spec.partition(":")
    try:  # the current directory's module, after the installed packages (never in place of one)
        fn = getattr(import_user_module(module, "--failure"), attr)
    except UserModuleError as e:
        raise bad_failure(spec, f"it cannot be imported ({str(e).removeprefix('--failure: ')})") from None
    except (ImportError, AttributeError, ValueError) as e:
        raise bad_failure(spec, f"it cannot be imported ({e})") from None
    if not callable(fn):
        raise bad_failure(spec, f"{module}.{attr} is {fn!r}, not callable")
    return fn


def labelled_env(cfg: DatagenConfig):
    """The unwrapped env of ``cfg`` (cached per process), checked against
    :class:`rmm_envs.risk.LabelledEnv`, or its risk adapter (:func:`rmm_envs.adapters.adapt`)
    where the env lacks the hooks (``TypeError`` naming the env and what is missing when
    neither serves)."""
    key = (cfg.env_id, json.dumps(cfg.env_kwargs, sort_keys=True), cfg.failure)
    if key not in _ENV_CACHE:
        if ":" not in cfg.env_id and cfg.env_id not in gym.registry:  # in a worker: the entry points register it
            load_env_plugins()
        try:
            env = gym.make(cfg.env_id, **cfg.env_kwargs)
        except Exception as e:  # noqa: BLE001 - any exception of the env's constructor: one line naming it
            raise ValueError(describe_env_error(e, cfg.env_id, cfg.env_kwargs, _env_kwargs_option)) from None
        hooks: Any
        try:
            check_labelled_env(env.unwrapped)
            hooks = env.unwrapped
            if cfg.failure is not None:
                raise ValueError(
                    f"failure (--failure) is for envs served by a risk adapter; {cfg.env_id} defines its own failures"
                )
        except TypeError:
            hooks = adapt(env, load_failure(cfg.failure))
        require = getattr(hooks, "require_labelling", None)
        if callable(require):  # an env built on a simulator of one's own names the hook it lacks, and the command
            require("rmm-datagen")
        _ENV_CACHE[key] = hooks
    return _ENV_CACHE[key]


def _env_kwargs_option(key: str, value: Any) -> str:
    """How ``rmm-datagen``'s user gave the env argument ``key``: ``--env-opt key=JSON``."""
    try:
        return f"--env-opt {key}={json.dumps(value)}"
    except (TypeError, ValueError):
        return f"--env-opt {key}={value!r}"


def config_seeds(seed: int, config_id: int) -> tuple[int, np.random.Generator]:
    """The env's reset seed and the sampling/labelling generator of one configuration."""
    env_seed = int(np.random.SeedSequence(seed, spawn_key=(config_id, 0)).generate_state(1)[0])
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(config_id, 1)))
    return env_seed, rng


def sensed_samples(env, env_seed: int, obs: np.ndarray) -> np.ndarray:
    """``obs`` as the env's sensors would report them under its disturbances (``obs`` itself
    without): one draw per configuration, from its env seed on the disturbances' own streams
    (so the states, the labels and every other draw are those of the undisturbed dataset), sample
    ``i`` at step ``i`` of that draw."""
    plan = getattr(env.unwrapped, "disturbance_plan", None)
    if plan is None or not plan.obs_ops:
        return obs
    draw = Realisation(plan.disturbances, plan.support, (env_seed, _DATASET_STREAM), plan)
    return observation_rows([draw] * len(obs), obs, [i * draw.dt for i in range(len(obs))])


#: the dataset's sensor draws, apart from an episode's with the same seed
_DATASET_STREAM = 0x6461_7461  # "data"


def label_configs(cfg: DatagenConfig, config_ids) -> pa.Table:
    """Generate, observe and label the samples of the given configurations (Algorithm 2)."""
    env = labelled_env(cfg)
    cols: dict[str, list] = {
        k: [] for k in ("config_id", "sample", "obs", "state", "risk", "min_risk_ctrl", "min_risk_ctrl_dur", "n_leaves")
    }
    for c in config_ids:
        env_seed, rng = config_seeds(cfg.seed, c)
        try:
            env.reset(seed=env_seed)
            states = env.sample_states(rng, cfg.samples_per_config)
            obs = sensed_samples(env, env_seed, env.observe_states(states, rng))
            est = RiskEstimator(env.risk_scene(), **cfg.estimator_params())
            res = est.estimate(states, rng)
            candidate_risk = (
                None
                if cfg.candidates is None
                else est.estimate_candidates(states, cfg.candidates, cfg.candidate_hold, rng)
            )
        except Exception as e:  # noqa: BLE001 - the env's, its simulator's or its driver's: one line naming it
            raise env_failure(e, cfg.env_id, f"labelling configuration {c} (--seed {cfg.seed})") from e
        n = states.shape[0]
        cols["config_id"].append(np.full(n, c, dtype=np.int32))
        cols["sample"].append(np.arange(n, dtype=np.int32))
        cols["obs"].append(obs.astype(np.float32))
        cols["state"].append(states.astype(np.float64))
        cols["risk"].append(res.risk)
        cols["min_risk_ctrl"].append(res.min_risk_ctrl)
        cols["min_risk_ctrl_dur"].append(res.min_risk_ctrl_dur)
        cols["n_leaves"].append(res.n_leaves.astype(np.int32))
        if candidate_risk is not None:
            cols.setdefault("candidate_risk", []).append(candidate_risk)
    arrays = {}
    for k, parts in cols.items():
        a = np.concatenate(parts)
        if a.ndim == 2:
            arrays[k] = pa.FixedSizeListArray.from_arrays(pa.array(a.reshape(-1)), a.shape[1])
        else:
            arrays[k] = pa.array(a)
    return pa.table(arrays)


def dataset_metadata(cfg: DatagenConfig) -> dict:
    """``metadata.json`` of the dataset ``cfg`` describes (the env is reset once if it has no
    episode yet, to read its scene's sizes)."""
    env = labelled_env(cfg)
    try:
        scene = env.risk_scene()
    except RuntimeError:  # the protocol's answer before the first reset
        try:
            env.reset(seed=0)
            scene = env.risk_scene()
        except Exception as e:  # noqa: BLE001 - the env's own: one line naming it
            raise env_failure(e, cfg.env_id, "reset(seed=0), to read its scene,") from e
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "env_id": cfg.env_id,
        "env_kwargs": cfg.env_kwargs,
        "configs": cfg.configs,
        "samples_per_config": cfg.samples_per_config,
        "seed": cfg.seed,
        "configs_per_shard": cfg.configs_per_shard,
        "failure": cfg.failure,
        "estimator": cfg.estimator_params()
        | {"policy": "uniform"}
        | ({} if cfg.candidates is None else {"candidates": cfg.candidates, "candidate_hold": cfg.candidate_hold}),
        "obs_dim": int(env.observation_space.shape[0]),
        "state_dim": int(scene.state_dim),
        "control_dim": len(scene.control_low),
        "obs_time_feature": env.dataset_notes()["obs_time_feature"],
        "package_version": rmm_envs.__version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
    }
