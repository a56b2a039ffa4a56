"""Wrappers: non-blocking (wall-clock) stepping, risk labelling, and the RL-ready guardian views."""

from rmm_envs.wrappers.nonblocking import NonBlockingStepping
from rmm_envs.wrappers.risk_label import RiskLabel
from rmm_envs.wrappers.rl import FlattenGuardianAction, GuardianReward

__all__ = ["FlattenGuardianAction", "GuardianReward", "NonBlockingStepping", "RiskLabel"]
