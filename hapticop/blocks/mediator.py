"""The application mediator: the one activity that owns every coordination decision.

It holds no ports: it reaches other activities only through the flags and Petri nets of
the composition. It runs on the main thread, in every schedule of that thread. Its
resource configuration starts the other threads; each cycle while running it steps the
nets through the flag maps.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hapticop.blocks.base import Block

if TYPE_CHECKING:
    from hapticop.runtime.system import System


class ApplicationMediator(Block):
    """Starts the threads, then fires the composition's nets each cycle."""

    system: "System | None" = None

    def attach_system(self, system: "System") -> None:
        self.system = system

    def configure_resources(self) -> bool:
        if self.system is None:
            raise RuntimeError("the mediator runs only in the main process of a system")
        return self.system.start_threads()

    def compute(self) -> None:
        self.system.coordinate()
