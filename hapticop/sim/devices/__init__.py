"""Simulated devices: each an activity that serves the bytes its real device would, on the device's link."""
