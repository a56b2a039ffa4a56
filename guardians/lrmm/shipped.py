"""The LRMM models this package ships: :data:`SHIPPED_BY_SYSTEM` (per system of
:data:`rmm_envs.catalog.SYSTEMS`, read from the registration file ``models/shipped.toml``, the one
place a shipped model names the systems it serves), :data:`SHIPPED` (the same by env id),
:func:`default_model_path` (the file of one env id and variant) and :func:`models_dir` (their
folder, where each model's decision file sits beside it).  :mod:`rmm_guardians.lrmm.model`
re-exports them."""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import gymnasium as gym
import tomllib

from rmm_envs.catalog import GUARDED_VARIANTS, SYSTEMS, current_id
from rmm_envs.defaults import DEFAULT_LABELLED_ENV

__all__ = [
    "DEFAULT_ENV",
    "REGISTRATION",
    "SHIPPED",
    "SHIPPED_BY_SYSTEM",
    "Shipped",
    "calibrated",
    "ShippedById",
    "default_model_path",
    "models_dir",
]

#: the env whose shipped model a guardian built without ``env_id`` or a model reads (the paper's case study)
DEFAULT_ENV = DEFAULT_LABELLED_ENV


@dataclass(frozen=True)
class Shipped:
    """What this package ships for one env id: its model file per variant and the observation
    field the model reads (``None``: the whole observation).  A model's ``lrmm`` decision
    (threshold, strategies, how they were chosen) is not here: it is the text file beside the
    model (``NAME.decision.toml``, :mod:`rmm_guardians.lrmm.decision`).  ``calibration``: how
    ``rmm-bench calibrate`` checks it (``model``, the variant it scores; ``labelling``, the
    training dataset's arguments besides the env; ``size``, the worlds and states it labels), or
    ``None``."""

    files: dict
    inputs: str | None = None
    calibration: dict | None = None


#: The file, beside the models, that registers each shipped model for the systems it serves.
REGISTRATION = "shipped.toml"
_FORMAT = "rmm-lrmm-shipped"


def _read_registration(path: Path) -> dict[str, dict[str, Shipped]]:
    """System name -> env variant -> :class:`Shipped`, from the registration file ``path``
    (``shipped.toml`` beside the models; its comments say what each entry is).  A malformed file
    is a ``ValueError`` naming the file, the entry and what was expected."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    if data.get("format") != _FORMAT or data.get("version") != 1:
        raise ValueError(
            f"{path}: expected format = {_FORMAT!r} and version = 1, got format = {data.get('format')!r} "
            f"and version = {data.get('version')!r}"
        )
    out: dict[str, dict[str, Shipped]] = {}
    for name, env_variants in data.get("systems", {}).items():
        for env_variant, entry in env_variants.items():
            files, inputs = entry.get("files"), entry.get("inputs")
            if env_variant not in ("plain", "guarded") or not isinstance(files, dict) or not files:
                raise ValueError(
                    f"{path}: [systems.{name}.{env_variant}] must be of env variant 'plain' or 'guarded' with a "
                    f"non-empty files table (variant = file), got env variant {env_variant!r} and files {files!r}"
                )
            if inputs is not None and not isinstance(inputs, str):
                raise ValueError(f"{path}: [systems.{name}.{env_variant}] inputs must be a field name, got {inputs!r}")
            calibration = entry.get("calibration")
            if calibration is not None:
                _check_calibration(path, f"[systems.{name}.{env_variant}]", calibration, files)
            out.setdefault(name, {})[env_variant] = Shipped(dict(files), inputs, calibration)
    return out


def _check_calibration(path: Path, where: str, calibration, files: dict) -> None:
    """``ValueError`` unless ``calibration`` names one of ``files``' variants and holds lists of
    strings (``labelling`` optional, ``size`` required)."""
    ok = isinstance(calibration, dict) and calibration.get("model") in files
    for key in ("labelling", "size"):
        value = calibration.get(key, [] if key == "labelling" else None) if ok else None
        ok = ok and isinstance(value, list) and all(isinstance(a, str) for a in value)
    if not ok or set(calibration) - {"model", "labelling", "size"}:
        raise ValueError(
            f"{path}: {where} calibration must be {{ model = one of {sorted(files)}, labelling = [strings], "
            f"size = [strings] }}, got {calibration!r}"
        )


def models_dir() -> Path:
    """The folder of the shipped model files, their decision files and :data:`REGISTRATION`."""
    return Path(str(resources.files("rmm_guardians.lrmm") / "models"))


#: The shipped models, per system of :data:`rmm_envs.catalog.SYSTEMS` (its ``name``) and env
#: variant (``"plain"``; ``"guarded"``: its blocking and non-blocking guardian envs), as
#: :data:`REGISTRATION` registers them.
SHIPPED_BY_SYSTEM: dict[str, dict[str, Shipped]] = _read_registration(models_dir() / REGISTRATION)


class ShippedById(dict):
    """:data:`SHIPPED_BY_SYSTEM` by env id (both twins of a system's guardian envs share an
    entry); a former id read from a stored record (:data:`rmm_envs.catalog.FORMER_IDS`) finds
    today's id's entry, though iteration lists today's ids only."""

    def __missing__(self, env_id):
        new = current_id(env_id) if isinstance(env_id, str) else env_id
        if new == env_id or not dict.__contains__(self, new):
            raise KeyError(env_id)
        return self[new]

    def __contains__(self, env_id) -> bool:
        return dict.__contains__(self, env_id) or (
            isinstance(env_id, str) and dict.__contains__(self, current_id(env_id))
        )

    def get(self, env_id, default=None):
        return self[env_id] if env_id in self else default


def _by_id() -> ShippedById:
    out = ShippedById()
    for system in SYSTEMS:
        for env_variant, ship in SHIPPED_BY_SYSTEM.get(system.name, {}).items():
            for env_id in system.ids(("plain",) if env_variant == "plain" else GUARDED_VARIANTS):
                out[env_id] = ship
    return out


#: The shipped model of each env id (:data:`SHIPPED_BY_SYSTEM`, looked up by id).
SHIPPED: ShippedById = _by_id()


def calibrated() -> dict[str, dict]:
    """System name -> how ``rmm-bench calibrate`` checks its shipped model, in the table's order:
    ``{"env": ["--env", ID, *labelling], "model": file, "size": [...]}``, from the entries of
    :data:`REGISTRATION` with a ``calibration`` (ID: the entry's env, plain or blocking guarded)."""
    out = {}
    for system in SYSTEMS:
        for env_variant, ship in SHIPPED_BY_SYSTEM.get(system.name, {}).items():
            if ship.calibration is not None:
                (env_id,) = system.ids((env_variant,))
                out[system.name] = {
                    "env": ["--env", env_id, *ship.calibration.get("labelling", [])],
                    "model": ship.files[ship.calibration["model"]],
                    "size": list(ship.calibration["size"]),
                }
    return out


def default_model_path(env_id: str = DEFAULT_ENV, variant: str = "paper") -> Path:
    """Path of the model shipped with the package for ``env_id`` (:data:`SHIPPED`).

    ``variant="paper"`` (default): the paper's risk-only network (Table II).  ``"act"``: the
    network the ``lrmm`` guardian uses (Dubins4D: with the action-conditioned head; the maze's
    parallel envs: the maze network; the quadrotor's parallel envs: the command model with its
    head).  ``"risk"`` (the quadrotor's parallel envs): the risk-only command model.
    """
    ship = SHIPPED.get(env_id)
    if ship is None and ":" not in env_id and env_id not in gym.registry:  # a module:Id registers when imported
        near = difflib.get_close_matches(env_id, list(gym.registry), n=1)
        raise ValueError(
            f"no env {env_id!r} is registered"
            + (f" (did you mean {near[0]!r}?)" if near else "")
            + f"; the shipped LRMM models are for {sorted(SHIPPED)}"
        )
    if ship is None:
        stem = env_id.rpartition(":")[2].lower().replace("-", "_")
        raise ValueError(
            f"no shipped LRMM model for {env_id!r} (shipped for {sorted(SHIPPED)}); make one from this env's "
            f"labelled states with two commands: rmm-datagen --env {env_id} --out data_{stem} and "
            f"rmm-train --data data_{stem} --out {stem}.npz; then give it: --agent-opt lrmm.model='\"{stem}.npz\"' "
            f'(in Python, model="{stem}.npz")'
        )
    if variant not in ship.files:
        raise ValueError(
            f"no shipped LRMM model for {env_id!r} (variant {variant!r}); its variants: {sorted(ship.files)}"
        )
    return models_dir() / ship.files[variant]
