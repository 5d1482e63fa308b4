"""SICK TiM5xx over CoLa A: codec (`cola`), framing (`stream`), cyclic client, loopback simulator.

Protocol facts and their confidence: ../shared/reference/sick-cola-a.md.
"""
