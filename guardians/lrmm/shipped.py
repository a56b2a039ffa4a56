"""The LRMM models this package ships: :data:`SHIPPED_BY_SYSTEM` (per system of
:data:`rmm_envs.catalog.SYSTEMS`), :data:`SHIPPED` (the same by env id),
:func:`default_model_path` (the file of one env id and variant) and :func:`models_dir` (their
folder, where each model's decision file sits beside it).  :mod:`rmm_guardians.lrmm.model`
re-exports them."""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import gymnasium as gym

from rmm_envs.catalog import GUARDED_KINDS, SYSTEMS, current_id

__all__ = ["DEFAULT_ENV", "SHIPPED", "SHIPPED_BY_SYSTEM", "Shipped", "ShippedById", "default_model_path", "models_dir"]

#: the env whose shipped model a guardian built without ``env_id`` or a model reads (the paper's case study)
DEFAULT_ENV = "Dubins4DGuarded-v0"


@dataclass(frozen=True)
class Shipped:
    """What this package ships for one env id: its model file per variant and the observation
    field the model reads (``None``: the whole observation).  A model's ``lrmm`` decision
    (threshold, strategies, how they were chosen) is not here: it is the text file beside the
    model (``NAME.decision.toml``, :mod:`rmm_guardians.lrmm.decision`)."""

    files: dict
    inputs: str | None = None


_DUBINS4D = Shipped({"paper": "dubins4d.npz", "act": "dubins4d_act.npz"})
#: The maze car under parallel autonomy reads the maze model (trained on ``Dubins3DMaze-v0``'s 8
#: rays) on its observation's ``"rays"`` field.
_MAZE_PARALLEL = Shipped({"act": "dubins3d_maze.npz"}, inputs="rays")

#: The quadrotor under parallel autonomy: ``lrmm`` reads the command model with the
#: action-conditioned head (``quadrotor_cmd_act.npz``: ``QuadrotorRoomGuarded-v0``'s labels under
#: random velocity commands to the stabilising controller, plus the risk of holding each of four
#: commands for 1 s: hover, climb, back off, back off and climb) on the whole observation (its
#: ``features`` leave out the orientation and the goal).  ``"risk"``: the risk-only command model
#: of Table II (``quadrotor_cmd.npz``, more labels, no head, no decision), for the core alone
#: (hover and level, ``strategies=""``) with an explicit threshold.
_QUAD_PARALLEL = Shipped({"act": "quadrotor_cmd_act.npz", "risk": "quadrotor_cmd.npz"})

#: The guarded envs around simulators the project did not write (rmm_envs/systems/cartpole, rmm_envs/systems/pendulum):
#: risk-only models of each env's own observation (the risk adapter's labels: random pushes held
#: for the adapter's default horizon, over half adapter-sampled and half driver-visited states),
#: applying the env's safe default (the balancing LQR) while the risk is above the threshold.
_CARTPOLE = Shipped({"act": "cartpole_guarded.npz"})
_PENDULUM = Shipped({"act": "inverted_pendulum_guarded.npz"})

#: The shipped models, per system of :data:`rmm_envs.catalog.SYSTEMS` (its ``name``) and kind of
#: env: ``"plain"`` (plain control) and ``"guarded"`` (its blocking and non-blocking guardian envs,
#: which share the world and the observation, so one entry serves both).
SHIPPED_BY_SYSTEM: dict[str, dict[str, Shipped]] = {
    "Dubins4D": {"guarded": _DUBINS4D},
    # the same car and observation on a map of your own: the circle-trained models, unchanged
    # (rays are distances whatever the obstacle's shape; how well that transfers is measured
    # in the map env's tests and docs, not assumed)
    "Dubins4DMap": {"guarded": _DUBINS4D},
    "Dubins3DMaze": {"plain": Shipped({"paper": "dubins3d_maze.npz"}), "guarded": _MAZE_PARALLEL},
    "QuadrotorRoom": {"plain": Shipped({"paper": "quadrotor.npz"}), "guarded": _QUAD_PARALLEL},
    "CartPole": {"guarded": _CARTPOLE},
    "InvertedPendulum": {"guarded": _PENDULUM},
}


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
        for kind, ship in SHIPPED_BY_SYSTEM.get(system.name, {}).items():
            for env_id in system.ids(("plain",) if kind == "plain" else GUARDED_KINDS):
                out[env_id] = ship
    return out


#: The shipped model of each env id (:data:`SHIPPED_BY_SYSTEM`, looked up by id).
SHIPPED: ShippedById = _by_id()


def models_dir() -> Path:
    """The folder of the shipped model files and their decision files."""
    return Path(str(resources.files("rmm_guardians.lrmm") / "models"))


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
