"""The `hapticop` command line: compose, validate, patch, graph, devices, bench."""

from hapticop.cli.main import app, main

__all__ = ["app", "main"]
