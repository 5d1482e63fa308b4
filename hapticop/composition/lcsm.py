"""The Life Cycle State Machine vocabulary shared by activities and threads.

States, super states, the progress flags an owner raises, and the requests the mediator
may send (see docs/coordination.md). The runtime implements the machine;
the validator uses the same names to know which flags exist and who writes them.
"""

from __future__ import annotations

from enum import IntEnum


class State(IntEnum):
    CREATION = 0
    RESOURCE_CONFIGURATION = 1
    CAPABILITY_CONFIGURATION = 2
    PAUSING = 3
    RUNNING = 4
    CLEANING = 5
    DONE = 6

    @property
    def flag_name(self) -> str:
        return self.name.lower()


# Super states: deploying ignores external coordination while it acquires resources;
# ready offers services.
DEPLOYING = frozenset({State.CREATION, State.RESOURCE_CONFIGURATION})
READY = frozenset({State.CAPABILITY_CONFIGURATION, State.PAUSING, State.RUNNING})
ACTIVE = frozenset(State) - {State.DONE}

# Raised by the owner as it makes progress (events: set once, consumed by a flag map).
PROGRESS_FLAGS = (
    "creation_complete",
    "resource_configuration_complete",
    "resource_configuration_failed",
    "capability_configuration_complete",
    "capability_configuration_failed",
    "running_complete",
    "deletion_complete",
)

# Written by the mediator's flag maps, read and cleared by the owner: go to that state.
REQUEST_FLAGS = (
    "request_resource_configuration",
    "request_capability_configuration",
    "request_pausing",
    "request_running",
    "request_cleaning",
    "request_creation",
)

STATE_FLAGS = tuple(state.flag_name for state in State)
