"""Moved to :mod:`rmm_envs.drivers.quadrotor`; importing this module warns (``DeprecationWarning``)
and gives that module's public names."""

from rmm_envs._deprecated import moved_module

moved_module(__name__, "rmm_envs.drivers.quadrotor", globals())
