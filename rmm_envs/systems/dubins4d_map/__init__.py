"""Dubins4D on a map of your own (``Dubins4DMap``): the Dubins4D car and driver among the shapes of
a JSON map (pymunk).  Its spec: :mod:`.system`."""
