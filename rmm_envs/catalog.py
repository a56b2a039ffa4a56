"""The table of systems: one declaration per system, from which every env id is derived.

:data:`SYSTEMS` holds one :class:`SystemSpec` per system: its dynamics, risk scenes, env entry
points, driver, safe default, the built-in guardians that apply, its docs page(s), and the ids
its results are keyed under.  Registration, ``rmm_envs.ENV_IDS`` and ``GUARDIAN_ENV_IDS``, the
stored-id mapping (:func:`stored_id`, :func:`current_id`), the shipped LRMM models' lookup, the
``--env`` help and the docs' environment list are all read from it.  Adding a system is its
modules plus one entry here.  Each system has up to three envs: ``<System>-v0`` (plain
control), ``<System>Guarded-v0`` (a built-in driver, a guardian may take over; blocking) and
``<System>Parallel-v0`` (the same, non-blocking).

What is derived from the table, and the stored ids: docs/decisions/0023-table-of-systems.md.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

import gymnasium as gym

__all__ = [
    "FORMER_IDS",
    "GUARDED_KINDS",
    "KINDS",
    "SYSTEMS",
    "DocPage",
    "SystemSpec",
    "current_id",
    "env_help",
    "guardian_env_ids",
    "guardian_envs_of",
    "env_ids",
    "register",
    "stored_id",
    "system",
    "system_of",
]

#: The three kinds of env a system may have, and the suffix of each one's id.
KINDS = {"plain": "-v0", "guarded": "Guarded-v0", "parallel": "Parallel-v0"}
#: The kinds with a built-in driver and a guardian action (the parallel-autonomy contract).
GUARDED_KINDS = ("guarded", "parallel")


@dataclass(frozen=True)
class DocPage:
    """A generated docs page: ``path`` under docs/, the module whose docstring it renders (the
    entry point of its first kind), its title (followed by the ids of ``kinds``), a figure."""

    path: str
    title: str
    kinds: tuple[str, ...]
    figure: str | None = None


@dataclass(frozen=True)
class SystemSpec:
    """One system.  References are ``"module:attribute"`` strings (imported only when used, so
    listing a system needs none of its optional dependencies)."""

    name: str  #: ids are ``name + KINDS[kind]``
    blurb: str  #: one line for the docs' environment list
    dynamics: str
    scenes: tuple[str, ...]  #: the RiskScene of each env (plain control first)
    envs: dict  #: kind -> entry point, for the kinds the system has
    driver: str | None = None  #: the built-in driver of its guarded envs
    safe_default: str | None = None  #: the SafeDefault its guardian action space carries
    guardians: tuple[str, ...] = ()  #: the built-in guardians that apply to its guarded envs
    vector: str | None = None  #: vector entry point of its blocking guardian env
    extra: str | None = None  #: the package extra its envs need
    pages: tuple[DocPage, ...] = ()
    #: kind -> the id that kind's results, datasets and fingerprints are keyed under, where it is
    #: not today's id (the id it was first recorded under; keys never change, so stored runs resume)
    stored: dict = field(default_factory=dict)

    def env_id(self, kind: str) -> str:
        if kind not in self.envs:
            raise KeyError(f"{self.name} has no {kind} env (it has {sorted(self.envs)})")
        return self.name + KINDS[kind]

    def ids(self, kinds=tuple(KINDS)) -> tuple[str, ...]:
        return tuple(self.name + KINDS[k] for k in kinds if k in self.envs)

    def make_safe_default(self, *args, **kwargs):
        """A new instance of the system's safe default (:attr:`safe_default`, the one place it is
        named), with the class's own arguments: what its guarded envs' action space carries."""
        if self.safe_default is None:
            raise ValueError(f"system {self.name} states no safe default")
        module, _, attr = self.safe_default.partition(":")
        return getattr(importlib.import_module(module), attr)(*args, **kwargs)


_DUBINS4D_GUARDIANS = ("lrmm", "lrmm-paper", "cbf", "cbf-paper", "hj", "hj-paper", "random", "inactive", "brakes")

SYSTEMS: tuple[SystemSpec, ...] = (
    SystemSpec(
        name="Dubins4D",
        blurb="a Dubins4D car driven to a goal among five circles by a reckless CLF-QP driver",
        dynamics="rmm_envs.dynamics.dubins4d:Dubins4D",
        scenes=("rmm_envs.scenes.dubins4d:Dubins4DScene",),
        envs={
            "guarded": "rmm_envs.envs.dubins4d:Dubins4DCirclesEnv",
            "parallel": "rmm_envs.envs.dubins4d:make_parallel_env",
        },
        driver="rmm_envs.drivers.dubins4d:CLFDriver",
        safe_default="rmm_envs.dynamics.dubins4d:FullBraking",
        guardians=_DUBINS4D_GUARDIANS,
        vector="rmm_envs.envs.dubins4d_vector:Dubins4DCirclesVectorEnv",
        pages=(
            DocPage(
                "environments/dubins4d.md",
                "Dubins4D among circles",
                ("guarded", "parallel"),
                "figures/dubins4d_frame.png",
            ),
        ),
        stored={"guarded": "Dubins4DCircles-v0"},
    ),
    SystemSpec(
        name="Dubins4DMap",
        blurb="the same car and driver on a JSON map of your own (circles, polygons, walls; pymunk)",
        dynamics="rmm_envs.dynamics.dubins4d:Dubins4D",
        scenes=("rmm_envs.scenes.dubins4d_map:Dubins4DMapScene",),
        envs={
            "guarded": "rmm_envs.envs.dubins4d_map:Dubins4DMapEnv",
            "parallel": "rmm_envs.envs.dubins4d_map:make_parallel_env",
        },
        driver="rmm_envs.drivers.dubins4d:CLFDriver",
        safe_default="rmm_envs.dynamics.dubins4d:FullBraking",
        guardians=("lrmm", "lrmm-paper", "random", "inactive", "brakes"),
        extra="map",
        pages=(
            DocPage(
                "environments/dubins4d_map.md",
                "Dubins4D on a map of your own",
                ("guarded", "parallel"),
                "figures/dubins4d_map_frame.png",
            ),
        ),
        stored={"guarded": "Dubins4DMap-v0"},
    ),
    SystemSpec(
        name="Dubins3DMaze",
        blurb="a constant-speed Dubins car in procedurally generated mazes, guarded from a corner-cutting pursuit driver",
        dynamics="rmm_envs.dynamics.dubins3d:Dubins3D",
        scenes=("rmm_envs.scenes.maze:MazeScene",),
        envs={
            "plain": "rmm_envs.envs.dubins3d_maze:Dubins3DMazeEnv",
            "guarded": "rmm_envs.envs.dubins3d_maze_parallel:Dubins3DMazeGuardedEnv",
            "parallel": "rmm_envs.envs.dubins3d_maze_parallel:make_parallel_env",
        },
        driver="rmm_envs.drivers.maze:PursuitDriver",
        safe_default="rmm_envs.envs.dubins3d_maze_parallel:TurnFromNearerWall",
        guardians=("lrmm", "cbf", "hj", "random", "inactive", "brakes"),
        pages=(
            DocPage(
                "environments/dubins3d_maze.md", "Dubins3D in mazes", ("plain",), "figures/dubins3d_maze_frame.png"
            ),
            DocPage(
                "environments/dubins3d_maze_parallel.md",
                "The maze car under parallel autonomy",
                ("guarded", "parallel"),
            ),
        ),
    ),
    SystemSpec(
        name="QuadrotorRoom",
        blurb="a quadrotor in procedurally generated rooms (PyBullet), flown through waypoints by a reckless pilot",
        dynamics="rmm_envs.dynamics.quadrotor:Quadrotor",
        scenes=("rmm_envs.scenes.quadrotor:QuadrotorScene", "rmm_envs.scenes.quadrotor:QuadrotorCommandScene"),
        envs={
            "plain": "rmm_envs.envs.quadrotor_room:QuadrotorRoomEnv",
            "guarded": "rmm_envs.envs.quadrotor_room_parallel:QuadrotorRoomGuardedEnv",
            "parallel": "rmm_envs.envs.quadrotor_room_parallel:make_parallel_env",
        },
        driver="rmm_envs.drivers.quadrotor:WaypointPilot",
        safe_default="rmm_envs.dynamics.quadrotor_control:HoverAndLevel",
        guardians=("lrmm", "cbf", "hj", "random", "inactive", "brakes"),
        extra="quadrotor",
        pages=(
            DocPage(
                "environments/quadrotor_room.md", "Quadrotor in rooms", ("plain",), "figures/quadrotor_room_frame.png"
            ),
            DocPage(
                "environments/quadrotor_room_parallel.md",
                "The quadrotor under parallel autonomy",
                ("guarded", "parallel"),
            ),
        ),
    ),
    # simulators the project did not write, made guarded envs by rmm_envs.envs.driven.guarded
    SystemSpec(
        name="CartPole",
        blurb="Gymnasium's CartPole-v1 driven to a target position by a reckless LQR, the balancing LQR as safe default",
        dynamics="gymnasium.envs.classic_control.cartpole:CartPoleEnv",
        scenes=("rmm_envs.adapters.classic_control:CartPoleScene",),
        envs={
            "guarded": "rmm_envs.envs.driven_examples:cartpole_guarded",
            "parallel": "rmm_envs.envs.driven_examples:cartpole_parallel",
        },
        driver="rmm_envs.envs.driven_examples:TargetTask",
        safe_default="rmm_envs.envs.driven:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        pages=(
            DocPage(
                "environments/driven_examples.md",
                "Simulators the project did not write, guarded",
                ("guarded", "parallel"),
            ),
        ),
    ),
    SystemSpec(
        name="InvertedPendulum",
        blurb="Gymnasium's MuJoCo InvertedPendulum-v5 under the same target task (see the CartPole page)",
        dynamics="gymnasium.envs.mujoco.inverted_pendulum_v5:InvertedPendulumEnv",
        scenes=("rmm_envs.adapters.mujoco_envs:MujocoScene",),
        envs={
            "guarded": "rmm_envs.envs.driven_examples:inverted_pendulum_guarded",
            "parallel": "rmm_envs.envs.driven_examples:inverted_pendulum_parallel",
        },
        driver="rmm_envs.envs.driven_examples:TargetTask",
        safe_default="rmm_envs.envs.driven:GivenSafeDefault",
        guardians=("lrmm", "random", "inactive", "brakes"),
        extra="mujoco",
    ),
)

#: Today's id -> the id its results are keyed under, where the two differ (:attr:`SystemSpec.stored`).
_STORED = {s.env_id(kind): old for s in SYSTEMS for kind, old in s.stored.items()}
#: An id found in a stored record (a results database, a dataset, a model's metadata) that is no
#: longer registered -> today's id of the same env.  Only records are read through it: these ids
#: are not registered and no command accepts them.
FORMER_IDS = {
    **{old: new for new, old in _STORED.items()},
    "Dubins4DCirclesGuarded-v0": "Dubins4DGuarded-v0",
    "Dubins4DCirclesParallel-v0": "Dubins4DParallel-v0",
}


def env_ids(kinds=tuple(KINDS)) -> tuple[str, ...]:
    """Every registered id of ``kinds``, system by system, plain control first."""
    return tuple(i for s in SYSTEMS for i in s.ids(kinds))


def guardian_env_ids() -> tuple[str, ...]:
    """The ids of every env with a built-in driver and a guardian action."""
    return env_ids(GUARDED_KINDS)


def system_of(env_id: str) -> tuple[SystemSpec, str]:
    """The system of ``env_id`` (today's id, or a former one read from a record) and its kind;
    KeyError for other ids."""
    env_id = current_id(env_id)
    for s in SYSTEMS:
        for kind in s.envs:
            if s.env_id(kind) == env_id:
                return s, kind
    raise KeyError(f"{env_id!r} is not an env of this package's systems ({', '.join(env_ids())})")


def system(name: str) -> SystemSpec:
    """The entry of :data:`SYSTEMS` named ``name``; KeyError naming the systems otherwise."""
    for s in SYSTEMS:
        if s.name == name:
            return s
    raise KeyError(f"no system {name!r}; the systems are {', '.join(s.name for s in SYSTEMS)}")


def guardian_envs_of(env_id: str) -> tuple[str, ...]:
    """The guardian envs (non-blocking first) of the system that ``env_id`` belongs to, or whose
    dynamics it is (``CartPole-v1`` for ``CartPole``); ``()`` for an env of no system."""
    system: SystemSpec | None
    try:
        system = system_of(env_id)[0]
    except KeyError:
        spec = gym.spec(env_id) if env_id in gym.registry else None
        system = next((s for s in SYSTEMS if spec is not None and s.dynamics == spec.entry_point), None)
    return () if system is None else system.ids(("parallel", "guarded"))


def env_help() -> str:
    """The ids ``--env`` accepts, as the CLI help lists them."""
    return (
        f"{', '.join(env_ids(('parallel',)))} (non-blocking) or {', '.join(env_ids(('guarded',)))} (blocking) "
        "in this package"
    )


def current_id(env_id: str) -> str:
    """Today's id of an id read from a stored record (:data:`FORMER_IDS`); any other id is itself."""
    return FORMER_IDS.get(env_id, env_id)


def stored_id(env_id: str) -> str:
    """The id the results of ``env_id`` are stored and keyed under: the id its system first
    recorded them under (:attr:`SystemSpec.stored`), so that results stored before an id changed
    keep their keys.  Accepts today's id or a former one."""
    env_id = current_id(env_id)
    return _STORED.get(env_id, env_id)


def register() -> None:
    """Register every env of :data:`SYSTEMS` (idempotent)."""
    for s in SYSTEMS:
        for kind, entry in s.envs.items():
            if s.env_id(kind) not in gym.registry:
                gym.register(
                    id=s.env_id(kind),
                    entry_point=entry,
                    vector_entry_point=s.vector if kind == "guarded" else None,
                    disable_env_checker=False,
                )
