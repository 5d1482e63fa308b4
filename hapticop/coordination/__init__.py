"""Coordination: Petri nets compiled once, fired by the mediator and explored by validation."""
