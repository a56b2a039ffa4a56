"""Guardians: policies that decide when to take control from the driver, and what to do."""
