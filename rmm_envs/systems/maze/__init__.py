"""The maze car (``Dubins3DMaze``): a constant-speed Dubins car in procedurally generated mazes, with
a corner-cutting pursuit driver.  Its spec: :mod:`.system`."""
