"""Simulated devices: activities that serve the bytes the real devices would, in the simulated world."""
