"""The built-in systems, one folder each; a system of your own is a folder (a package) like these.

A folder holds everything of one system: ``system.py`` (its :class:`rmm_envs.catalog.SystemSpec`,
naming every other part once), and the parts it names: dynamics, world and starts, driver, safe
default, risk scene, env(s), view and doomed-start test.  The folder is registered through the
entry-point group ``rmm_envs.systems`` (:mod:`rmm_envs.builtin` lists this package's), exactly as a
package of yours registers its own (docs/tutorials/own-simulator.md).  Nothing outside a folder
imports it except its registration, another system built on it (the map variant and the maze car
reuse the Dubins4D car's arithmetic) and a guardian method's part for it (``guardians/``).
Importing this package imports no system.
"""
