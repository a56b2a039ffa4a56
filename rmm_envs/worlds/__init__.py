"""Obstacle families: generation, exact collision tests and ray sensing (one file per family)."""

from rmm_envs.worlds.circles import (
    CircleWorld,
    first_contact,
    points_in_circles,
    ray_cast,
    segments_hit_circles,
)

__all__ = ["CircleWorld", "first_contact", "points_in_circles", "ray_cast", "segments_hit_circles"]
