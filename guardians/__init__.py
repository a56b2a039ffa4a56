"""Guardians: policies that decide when to take control from the driver, and what to do.

>>> from rmm_guardians import make_guardian
>>> g = make_guardian("brakes", turn="zero")
"""

from rmm_guardians.base import Guardian
from rmm_guardians.registry import available_guardians, make_guardian
from rmm_guardians.wrapped import CallableGuardian, SB3Guardian

__all__ = ["CallableGuardian", "Guardian", "SB3Guardian", "available_guardians", "make_guardian"]
