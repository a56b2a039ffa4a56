"""Dubins4D among circles (``Dubins4D``): a car with heading-rate and acceleration controls driven
to a goal among five circles by a reckless CLF-QP driver.  Its spec: :mod:`.system`."""
