"""The application mediator: the one activity that owns every coordination decision.

It holds no ports: it reaches other activities only through the flags and Petri nets of
the composition. It runs on the main thread, in every schedule of that thread.
"""

from __future__ import annotations

from hapticop.blocks.base import Block


class ApplicationMediator(Block):
    """Fires the composition's nets each cycle and walks every LCSM."""
