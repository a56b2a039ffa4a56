"""The table of systems: one :class:`SystemSpec` per system, from which every env id is derived.

:data:`SYSTEMS` holds each system's dynamics, risk scenes, env entry points, driver, safe
default, view, doomed-start test, the guardians that apply, docs pages and stored ids;
registration, ``rmm_envs.ENV_IDS``, the stored ids (:func:`stored_id`, :func:`current_id`), the
``--env`` help and the docs' environment list are read from it.  Ids: ``<System>-v0`` (plain
control), ``<System>Guarded-v0`` (a built-in driver a guardian may override; blocking) and
``<System>Parallel-v0`` (the same, non-blocking).

Every system, this package's own included (:mod:`rmm_envs.builtin`), registers through the
entry-point group :data:`ENTRY_POINT_GROUP`, ``rmm_envs.systems`` (:func:`add_system` says how);
the table is filled from it on import.  :func:`system_of` finds an id's system,
:func:`system_of_env` an env's.  Why, and the order of the table:
docs/decisions/0023-table-of-systems.md.
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass, field
from importlib.metadata import entry_points

import gymnasium as gym

__all__ = [
    "ENTRY_POINT_GROUP",
    "FORMER_IDS",
    "GUARDED_VARIANTS",
    "ENV_VARIANTS",
    "SYSTEMS",
    "DocPage",
    "SystemSpec",
    "add_system",
    "current_id",
    "env_help",
    "env_ids",
    "guardian_env_ids",
    "guardian_envs_of",
    "load_ref",
    "register",
    "stored_id",
    "system",
    "system_of",
    "system_of_env",
]

#: The three env variants a system may have, and the suffix of each one's id.
ENV_VARIANTS = {"plain": "-v0", "guarded": "Guarded-v0", "parallel": "Parallel-v0"}
#: The env variants with a built-in driver and a guardian action (the parallel-autonomy contract).
GUARDED_VARIANTS = ("guarded", "parallel")
#: The entry-point group every system is registered through (:func:`add_system`).
ENTRY_POINT_GROUP = "rmm_envs.systems"
#: The distribution of this package: its systems come first in the table.
_OWN = "rmm-envs"


def load_ref(ref: str):
    """The object a ``"module:attribute"`` reference names (the attribute may be dotted)."""
    module, _, attr = ref.partition(":")
    obj = importlib.import_module(module)
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj


@dataclass(frozen=True)
class DocPage:
    """A generated docs page: ``path`` under docs/, the module whose docstring it renders (the
    entry point of its first variant), its title (followed by the ids of ``variants``), a figure."""

    path: str
    title: str
    variants: tuple[str, ...]
    figure: str | None = None


@dataclass(frozen=True)
class SystemSpec:
    """One system.  References are ``"module:attribute"`` strings (imported only when used, so
    listing a system needs none of its optional dependencies)."""

    name: str  #: ids are ``name + ENV_VARIANTS[variant]``
    blurb: str  #: one line for the docs' environment list
    dynamics: str
    scenes: tuple[str, ...]  #: the RiskScene of each env (plain control first)
    envs: dict  #: variant -> entry point, for the variants the system has
    driver: str | None = None  #: the built-in driver of its guarded envs
    safe_default: str | None = None  #: the SafeDefault its guardian action space carries
    guardians: tuple[str, ...] = ()  #: the built-in guardians that apply to its guarded envs
    vector: str | None = None  #: vector entry point of its blocking guardian env
    extra: str | None = None  #: the package extra its envs need
    pages: tuple[DocPage, ...] = ()
    #: variant -> the id that variant's results, datasets and fingerprints are keyed under, where it is
    #: not today's id (the id it was first recorded under; keys never change, so stored runs resume)
    stored: dict = field(default_factory=dict)
    #: ids found in older records -> the variant they are today (read back, never registered)
    former: dict = field(default_factory=dict)
    #: ``factory(env, size) -> View`` that draws its guarded envs (rmm_envs.views.view_for);
    #: ``None``: the env's own ``rgb_array`` frame
    view: str | None = None
    #: ``test(env) -> StartAssessment`` of its guarded envs' starts, called right after ``reset``
    #: and leaving the env as it found it (rmm_envs.starts.assess_start); ``None``: not assessed
    doomed_test: str | None = None

    def env_id(self, variant: str) -> str:
        if variant not in self.envs:
            raise KeyError(f"{self.name} has no {variant} env (it has {sorted(self.envs)})")
        return self.name + ENV_VARIANTS[variant]

    def ids(self, variants=tuple(ENV_VARIANTS)) -> tuple[str, ...]:
        return tuple(self.name + ENV_VARIANTS[k] for k in variants if k in self.envs)

    def make_safe_default(self, *args, **kwargs):
        """A new instance of the system's safe default (:attr:`safe_default`, the one place it is
        named), with the class's own arguments: what its guarded envs' action space carries."""
        if self.safe_default is None:
            raise ValueError(f"system {self.name} states no safe default")
        return load_ref(self.safe_default)(*args, **kwargs)


#: Every registered system, in registration order (module docstring); read it, add through :func:`add_system`.
SYSTEMS: tuple[SystemSpec, ...] = ()
#: Today's id -> the id its results are keyed under, where the two differ (:attr:`SystemSpec.stored`).
_STORED: dict[str, str] = {}
#: An id found in a stored record (a results database, a dataset, a model's metadata) that is no
#: longer registered -> today's id of the same env (:attr:`SystemSpec.stored` and
#: :attr:`SystemSpec.former`).  Only records are read through it: these ids are not registered
#: and no command accepts them.
FORMER_IDS: dict[str, str] = {}


def _derive() -> None:
    """Refill :data:`_STORED` and :data:`FORMER_IDS` (in place) from :data:`SYSTEMS`."""
    _STORED.clear()
    _STORED.update({s.env_id(variant): old for s in SYSTEMS for variant, old in s.stored.items()})
    FORMER_IDS.clear()
    FORMER_IDS.update({old: new for new, old in _STORED.items()})
    FORMER_IDS.update({old: s.env_id(variant) for s in SYSTEMS for old, variant in s.former.items()})


def _register(s: SystemSpec) -> None:
    for variant, entry in s.envs.items():
        if s.env_id(variant) not in gym.registry:
            gym.register(
                id=s.env_id(variant),
                entry_point=entry,
                vector_entry_point=s.vector if variant == "guarded" else None,
                disable_env_checker=False,
            )


def add_system(*specs: SystemSpec) -> None:
    """Add ``specs`` to :data:`SYSTEMS` and register their env ids with Gymnasium: the one way a
    system enters the table.  A package registers its systems with an entry point of
    :data:`ENTRY_POINT_GROUP` whose value is a function returning a :class:`SystemSpec` (or
    several), or a ``SystemSpec`` itself; importing ``rmm_envs`` passes each to this function,
    this package's entry point first (the built-ins, in the table's order), then other
    distributions' by name (one that fails is a warning naming it, its systems left out)::

        [project.entry-points."rmm_envs.systems"]
        MyRobot = "my_robot.system:spec"

    A script may call it directly.  A spec already in the table is left as it is; a second system
    of the same name, or an id Gymnasium already has under another entry point, is refused
    (``ValueError`` naming it)."""
    global SYSTEMS
    for spec in specs:
        if not isinstance(spec, SystemSpec):
            raise TypeError(f"a system is a rmm_envs.catalog.SystemSpec, got {spec!r}")
        if spec in SYSTEMS:
            continue
        if any(s.name == spec.name for s in SYSTEMS):
            raise ValueError(f"a system named {spec.name!r} is already registered; a system's name is its ids' stem")
        for variant, entry in spec.envs.items():
            if variant not in ENV_VARIANTS:
                raise ValueError(f"system {spec.name!r}: env variant {variant!r} is not one of {list(ENV_VARIANTS)}")
            known = gym.registry.get(spec.env_id(variant))
            if known is not None and known.entry_point != entry:
                raise ValueError(
                    f"system {spec.name!r}: the id {spec.env_id(variant)!r} is already registered with entry point "
                    f"{known.entry_point!r}, not {entry!r}"
                )
        SYSTEMS = (*SYSTEMS, spec)
        _derive()
        _register(spec)


def _load_entry_points() -> None:
    """Fill the table from :data:`ENTRY_POINT_GROUP`: this package's entry points first, in the
    order it declares them, then other distributions' by name.  This package's failing is an
    error; another's is a warning naming it, and its systems are left out."""

    def dist(ep) -> str:
        return ep.dist.name if ep.dist is not None else ""

    eps = sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: (dist(ep) != _OWN, dist(ep)))
    if not any(dist(ep) == _OWN for ep in eps):
        raise ImportError(
            f"rmm_envs: no '{ENTRY_POINT_GROUP}' entry points of {_OWN!r} are installed (its built-in "
            "systems register through them); reinstall the package, e.g. pip install -e ."
        )
    for ep in eps:
        try:
            found = ep.load()
            found = found() if callable(found) and not isinstance(found, SystemSpec) else found
            add_system(*((found,) if isinstance(found, SystemSpec) else found))
        except Exception as e:
            if dist(ep) == _OWN:
                raise
            warnings.warn(
                f"rmm_envs: the '{ENTRY_POINT_GROUP}' entry point {ep.name} = {ep.value!r} of {dist(ep)!r} failed "
                f"({type(e).__name__}: {e}); its systems are not registered",
                RuntimeWarning,
                stacklevel=2,
            )


def env_ids(variants=tuple(ENV_VARIANTS)) -> tuple[str, ...]:
    """Every registered id of ``variants``, system by system, plain control first."""
    return tuple(i for s in SYSTEMS for i in s.ids(variants))


def guardian_env_ids() -> tuple[str, ...]:
    """The ids of every env with a built-in driver and a guardian action."""
    return env_ids(GUARDED_VARIANTS)


def system_of(env_id: str) -> tuple[SystemSpec, str]:
    """The system of ``env_id`` (today's id, or a former one read from a record) and its variant;
    KeyError for other ids."""
    env_id = current_id(env_id)
    for s in SYSTEMS:
        for variant in s.envs:
            if s.env_id(variant) == env_id:
                return s, variant
    raise KeyError(f"{env_id!r} is not an env of this package's systems ({', '.join(env_ids())})")


def system_of_env(env) -> tuple[SystemSpec, str] | None:
    """The system an env instance (wrapped or not) belongs to, and its variant: by the id it was made
    under (``env.unwrapped.spec``), else by its class or a base class being one a system's envs
    name (a subclass, an env built without ``gym.make``), else by its class being a system's
    dynamics (variant ``"dynamics"``: the simulator of ``CartPole`` is ``CartPole-v1``'s env);
    ``None`` for an env of no system."""
    u = env.unwrapped
    spec = getattr(u, "spec", None)
    if spec is not None and isinstance(getattr(spec, "id", None), str):
        try:
            return system_of(spec.id)
        except KeyError:
            pass
    for cls in type(u).__mro__:
        ref = f"{cls.__module__}:{cls.__qualname__}"
        for s in SYSTEMS:
            variant = next((k for k, entry in s.envs.items() if entry == ref), None)
            if variant is not None:
                return s, variant
            if s.dynamics == ref:
                return s, "dynamics"
    return None


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
    """Register every env of :data:`SYSTEMS` with Gymnasium (idempotent; :func:`add_system` does it too)."""
    for s in SYSTEMS:
        _register(s)


_load_entry_points()
