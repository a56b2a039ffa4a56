"""Wrappers: non-blocking (wall-clock) stepping and risk labelling."""

from rmm_envs.wrappers.nonblocking import NonBlockingStepping

__all__ = ["NonBlockingStepping"]
