"""Named observation fields: :class:`ObservationLayout` (named slices of a flat observation and the
rays' directions), :class:`ObservationBox` (a ``Box`` carrying one) and :func:`layout`.

Part of the parallel-autonomy contract, and importable from :mod:`rmm_envs.autonomy` as such.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from rmm_envs.machine_independent import wrap_angle

__all__ = ["ObservationBox", "ObservationLayout", "layout"]


@dataclass(frozen=True)
class ObservationLayout:
    """Named slices of a flat observation vector.

    Args:
        fields: ``(name, start, stop)`` triples: ``obs[start:stop]`` is the field ``name``.
            Fields do not overlap and cover ``range(size)`` without gaps.
        ray_angles: direction of each ray of the ``"rays"`` field relative to the heading, in
            radians counter-clockwise (empty when there are no rays).
    """

    fields: tuple[tuple[str, int, int], ...]
    ray_angles: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        pos = 0
        names = set()
        for name, start, stop in self.fields:
            if start != pos or stop <= start or name in names:
                raise ValueError(f"layout fields must be distinct, contiguous and non-empty from 0, got {self.fields}")
            names.add(name)
            pos = stop
        if "rays" in names and len(self.ray_angles) != self.size_of("rays"):
            raise ValueError(f"ray_angles needs one angle per ray ({self.size_of('rays')}), got {len(self.ray_angles)}")

    @classmethod
    def of(cls, *sizes: tuple[str, int], ray_angles: Sequence[float] = ()) -> ObservationLayout:
        """A layout from ``(name, length)`` pairs in order, e.g. ``of(("time", 1), ("rays", 12))``."""
        fields, pos = [], 0
        for name, n in sizes:
            fields.append((name, pos, pos + int(n)))
            pos += int(n)
        return cls(tuple(fields), tuple(float(a) for a in ray_angles))

    @property
    def size(self) -> int:
        return self.fields[-1][2] if self.fields else 0

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f[0] for f in self.fields)

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def __getitem__(self, name: str) -> slice:
        for f, start, stop in self.fields:
            if f == name:
                return slice(start, stop)
        raise KeyError(f"the observation has no field {name!r}; it has {list(self.names)}")

    def size_of(self, name: str) -> int:
        s = self[name]
        return s.stop - s.start

    def index(self, name: str) -> int:
        """The position of a one-number field."""
        s = self[name]
        if s.stop - s.start != 1:
            raise ValueError(f"field {name!r} has {s.stop - s.start} numbers, not one; use layout[{name!r}]")
        return s.start

    def ray_index(self, angle: float) -> int:
        """Position in the observation of the ray nearest to ``angle`` (radians from the heading)."""
        if not self.ray_angles:
            raise KeyError(f"the observation has no rays; it has {list(self.names)}")
        d = wrap_angle(np.asarray(self.ray_angles, dtype=float) - float(angle))
        return self["rays"].start + int(np.argmin(np.abs(d)))


class ObservationBox(spaces.Box):
    """A Gymnasium ``Box`` observation space with an :class:`ObservationLayout` (``.layout``)."""

    def __init__(self, low, high, layout: ObservationLayout, dtype=np.float32, seed=None) -> None:
        super().__init__(low, high, dtype=dtype, seed=seed)
        if self.shape != (layout.size,):
            raise ValueError(f"layout describes {layout.size} numbers but the box has shape {self.shape}")
        self.layout = layout


def layout(space) -> ObservationLayout:
    """The layout of an observation space, or a ``TypeError`` saying the space has none."""
    lay = getattr(space, "layout", None)
    if not isinstance(lay, ObservationLayout):
        raise TypeError(f"observation space {space!r} carries no layout (expected rmm_envs.autonomy.ObservationBox)")
    return lay
