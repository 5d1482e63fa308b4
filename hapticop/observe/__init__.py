"""Observing a run: what is recorded of it and what is made again from a recording."""
