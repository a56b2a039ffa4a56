"""Guardians: policies that decide when to take control from the driver, and what to do.

>>> from guardians import make_guardian
>>> g = make_guardian("brakes", turn="zero")
"""

from guardians.adapters import CallableGuardian, SB3Guardian
from guardians.base import Guardian
from guardians.registry import available_guardians, make_guardian

__all__ = ["CallableGuardian", "Guardian", "SB3Guardian", "available_guardians", "make_guardian"]
