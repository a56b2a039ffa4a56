"""A guardian method's per-system parts: the class that models one dynamics with the method.

One guardian name (``cbf``, ``hj``) serves several systems: its own class models one dynamics
and hands each other to a **part** (the quadrotor's CBF rows, the maze car's HJ look-ahead),
found by the method's name and the dynamics name the env's action space states, never by a
system's name (:class:`rmm_guardians.dispatch.DynamicsDispatch`).  Every part registers through
the entry-point group :data:`ENTRY_POINT_GROUP` (``"<method>.<dynamics>" = "module:Class"``), this
package's own in its pyproject.toml exactly as a package of yours declares one;
:func:`register_part` adds one in the current process; :func:`parts_of` lists a method's parts.
What a part class states: :func:`parts_of`.
"""

from __future__ import annotations

import warnings
from importlib.metadata import entry_points

from rmm_envs.catalog import load_ref

__all__ = ["ENTRY_POINT_GROUP", "parts_of", "register_part"]

#: The entry-point group of the methods' parts: ``"<method>.<dynamics>" = "module:Class"``.
ENTRY_POINT_GROUP = "rmm_guardians.parts"
#: The distribution of this package (its parts come first; without them its install is stale).
_OWN = "rmm-envs"

_REGISTERED: dict[str, dict[str, object]] = {}  # method -> dynamics name -> class or "module:Class"


def register_part(method: str, dynamics_name: str, part) -> None:
    """Serve the dynamics ``dynamics_name`` under the guardian method ``method`` (``"cbf"``, ``"hj"``)
    with ``part``: a guardian class, or ``"module:Class"`` imported when first used; in this process."""
    for what, value in (("method", method), ("dynamics_name", dynamics_name)):
        if not isinstance(value, str) or not value:
            raise ValueError(f"register_part: {what} must be a non-empty string, got {value!r}")
    if not isinstance(part, type) and not (isinstance(part, str) and ":" in part):
        raise ValueError(f"register_part: part must be a guardian class or 'module:Class', got {part!r}")
    _REGISTERED.setdefault(method, {})[dynamics_name] = part


def _load(ref) -> type:
    return ref if isinstance(ref, type) else load_ref(ref)


def _declared(method: str) -> dict[str, type]:
    """dynamics name -> part of ``method`` from the entry points (see :func:`parts_of` for the order)."""

    def dist(ep) -> str:
        return ep.dist.name if ep.dist is not None else ""

    eps = sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: (dist(ep) != _OWN, dist(ep), ep.name))
    if not any(dist(ep) == _OWN for ep in eps):
        raise RuntimeError(
            f"rmm_guardians: no '{ENTRY_POINT_GROUP}' entry points of {_OWN!r} are installed (its methods' "
            "per-system parts register through them); reinstall the package, e.g. pip install -e ."
        )
    found: dict[str, type] = {}
    for ep in eps:
        of, dot, name = ep.name.partition(".")
        if of != method:
            continue
        try:
            if not dot or not name:
                raise ValueError(f"the name must be '<method>.<dynamics>', got {ep.name!r}")
            found[name] = ep.load()
        except Exception as e:
            if dist(ep) == _OWN:
                raise
            warnings.warn(
                f"rmm_guardians: the '{ENTRY_POINT_GROUP}' entry point {ep.name} = {ep.value!r} of {dist(ep)!r} "
                f"failed ({type(e).__name__}: {e}); {method!r} does not serve those dynamics",
                RuntimeWarning,
                stacklevel=3,
            )
    return found


def parts_of(method: str) -> dict[str, type]:
    """dynamics name -> the class that models those dynamics for the guardian method ``method``:
    this package's entry points, then other distributions' (by distribution, then name; one
    that fails is a warning naming it), then :func:`register_part`'s, a later one for the same
    dynamics replacing an earlier one.  A package declares one as::

        [project.entry-points."rmm_guardians.parts"]
        "cbf.double_integrator" = "my_robot.cbf_part:DoubleIntegratorCBF"

    A part is a guardian class built with keyword arguments that states ``serves`` (how a
    refusal names what it models, ``"the maze car"``), ``controls`` (its dynamics' control
    names) and ``option`` (the method's settings field holding its arguments, ``"maze"`` for
    ``cbf``'s ``maze={...}``, whose ``False`` refuses those envs; ``None``, or a field the
    method's settings lack: built with the arguments the method's parts share)."""
    parts = _declared(method)
    parts.update({name: _load(ref) for name, ref in _REGISTERED.get(method, {}).items()})
    return parts
