"""The quadrotor in rooms (``QuadrotorRoom``, PyBullet): a body, its cascaded controller, generated
rooms and a reckless waypoint pilot.  Its spec: :mod:`.system`."""
