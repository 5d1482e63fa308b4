"""The application mediator: the one activity that owns every coordination decision.

It holds no ports: it reaches other activities only through the flags and Petri nets of
the composition. It runs on the main thread, in every schedule of that thread. Its
resource configuration starts the other threads; each cycle while running it steps the
nets through the flag maps. Both go through the coordination handle in its context, which
only the main process of a system provides.
"""

from __future__ import annotations

from hapticop.blocks.base import Block


class ApplicationMediator(Block):
    """Starts the threads, then fires the composition's nets each cycle."""

    def configure_resources(self) -> bool:
        if self.context.coordination is None:
            raise RuntimeError("the mediator runs only in the main process of a system")
        return self.context.coordination.start_threads()

    def compute(self) -> None:
        self.context.coordination.step()
