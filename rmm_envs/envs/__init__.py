"""Gymnasium shells: a system + a world + a driver + bookkeeping."""
