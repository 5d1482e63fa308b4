"""Declared experiments: a composition, its factors, seeds and targets, run on a pool or a Ray cluster."""
