"""Moved: the worker pool is :mod:`rmm_envs.pool` ("parallel" names the non-blocking envs).
Importing this module warns (``DeprecationWarning``) and gives the pool's public names."""

from rmm_envs._deprecated import moved_module

moved_module(__name__, "rmm_envs.pool", globals())
