"""The recorder's view of each activity's cycle ring (`runtime.cycle_log`): how deep, and what the file says of it."""

from __future__ import annotations

from hapticop.composition.loader import Loaded
from hapticop.recording.mcapfile import StreamInfo
from hapticop.recording.plan import recorded_cycles
from hapticop.runtime.cycle_log import port_of, stream_of


def capacities(loaded: Loaded) -> dict[str, int]:
    """The ring each scheduled activity's cycles get, by the name of their stream (the observer reserves them)."""
    plan = recorded_cycles(loaded.composition)
    return {stream_of(activity): recorded.capacity for activity, recorded in plan.items()}


def recorded(loaded: Loaded, layout) -> list[tuple[StreamInfo, int, int, int]]:
    """(what the file says of it, offset, bytes, capacity) of each activity's cycle ring the layout placed."""
    plan = recorded_cycles(loaded.composition)
    rings = []
    for activity, transport in layout.cycles.items():
        resolved = loaded.activities[activity]
        port = port_of(resolved.interface, resolved.block.implements_flush())
        info = StreamInfo(transport.stream, "int64", tuple(port.shape), "1", plan[activity].rate_hz, 1,
                          f"{activity}.cycles", (), port.doc)
        rings.append((info, transport.offset, transport.nbytes, plan[activity].capacity))
    return rings
