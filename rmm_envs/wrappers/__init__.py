"""Wrappers: non-blocking (wall-clock) stepping and risk labelling."""

from rmm_envs.wrappers.nonblocking import NonBlockingStepping
from rmm_envs.wrappers.risk_label import RiskLabel

__all__ = ["NonBlockingStepping", "RiskLabel"]
