"""Streams with `ros2:`: the hapticop port fits the message (docs/ros2.md's table, in ros2/messages.py).

The stream's other side is the generated node's port, declared from the option itself; so instead of
the ordinary dtype/shape/unit comparison (structure.streams leaves these streams to this check), the
finding names the message, what it takes, and the field to change.
"""

from __future__ import annotations

from collections.abc import Iterator

from hapticop.composition import graph as G
from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.ros2streams import ROS2
from hapticop.ros2.messages import describe, layout_of


def ports(cg: G.CompositionGraph) -> Iterator[Diagnostic]:
    """A hapticop port carried by a `ros2:` stream fits its message type, shape and unit."""
    loaded = cg.loaded
    for name, stream in loaded.composition.streams.items():
        option = stream.ros2
        if option is None:
            continue
        path = ("streams", name, "ros2")
        for ref in [stream.writer, *stream.readers]:
            activity, port_name = ref.split(".", 1)
            resolved = loaded.activities.get(activity)
            if activity == ROS2 or resolved is None:
                continue
            port = {**resolved.interface.outputs, **resolved.interface.inputs}.get(port_name)
            if port is None:
                continue  # reported as an unknown port
            layout = layout_of(option.type, port.dtype, port.shape)
            if layout is None:
                yield Diagnostic("ros2-message", f"'{ref}' is {port.describe()}: it does not fit {option.type}",
                                 path + ("type",), expected=describe(option.type),
                                 hint="carry a port of one of these layouts, or choose another message type")
            elif tuple(port.shape) != option.port_shape:
                yield Diagnostic("ros2-message", f"'{ref}' is {port.describe()} but the topic is declared "
                                 f"{layout.dtype}{list(option.port_shape)}", path + ("shape",),
                                 expected=str(list(port.shape)), hint=f"write 'shape: {list(port.shape)}'")
            elif port.unit != layout.unit:
                yield Diagnostic("ros2-unit", f"'{ref}' is in [{port.unit}] but {option.type} carries "
                                 f"[{layout.unit}] ({layout.doc})", path + ("type",), expected=layout.unit,
                                 hint="convert it first (a gain block) or choose the message that carries it")


CHECKS = (ports,)
