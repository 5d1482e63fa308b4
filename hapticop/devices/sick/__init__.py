"""SICK TiM5xx over CoLa A: codec (`cola`), framing (`stream`), cyclic client, loopback simulator.

Protocol facts and their confidence: docs/devices/sick-tim561.md.
"""
