"""The built-in drivers of the guarded envs: the reckless agents a guardian may override.

* :mod:`rmm_envs.drivers.dubins4d`: :class:`~rmm_envs.drivers.dubins4d.CLFDriver`, the Dubins4D
  car's CLF-QP driver toward the goal (obstacles ignored);
* :mod:`rmm_envs.drivers.maze`: :class:`~rmm_envs.drivers.maze.PursuitDriver`, the maze car's
  corner-cutting pure pursuit along the cell path, and the maze's cell graph helpers;
* :mod:`rmm_envs.drivers.quadrotor`: :class:`~rmm_envs.drivers.quadrotor.WaypointPilot`, the
  quadrotor's straight-line waypoint pilot on the cascaded controller.

Each system's driver is named in its entry of :data:`rmm_envs.catalog.SYSTEMS`.
"""
