"""Teleoperation across a network: what moves samples between hosts, and a link to test them on."""
