"""Streams that ROS 2 sees: a stream's `ros2:` option, and the ROS 2 node the loader writes for them.

A stream with `ros2:` and no `to:` is published to ROS 2; one with `ros2:` and no `from:` is subscribed
from it. The user writes no bridge: like the hosts' split (placement.py), `expand` rewrites the YAML tree
so that these streams end or start at a generated `ros2_bridge` activity (`ros2`) on a thread of its own
in its own process, configured by the system's `ros2:` node (docs/ros2.md). The tree's nodes are kept, so
findings on the streams stay located in the file.
"""

from __future__ import annotations

import copy
from typing import Any

from pydantic import Field, ValidationError

from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.units import Duration
from hapticop.ros2 import names
from hapticop.ros2.topics import Ros2Node, Ros2Topic

ROS2 = "ros2"
"""The generated node's activity and thread."""


class Ros2Stream(Ros2Topic):
    """A stream's ROS 2 topic: published when the stream has no `to:`, subscribed when it has no `from:`."""

    distro: names.Distro | None = Field(None, description="the distribution, if said here: it must be the "
                                        "system's (`ros2: {distro: ...}`), one node speaking one distribution")


class Ros2System(Ros2Node):
    """The ROS 2 node that carries the composition's `ros2:` streams."""

    period: Duration = Field(5_000_000, description="the node's cycle (topics are published at their own "
                             "rates, taken each cycle)")


def has_ros2(tree: Any) -> bool:
    streams = tree.get("streams") if isinstance(tree, dict) else None
    return isinstance(streams, dict) and any(isinstance(e, dict) and "ros2" in e for e in streams.values())


def expand(tree: Any) -> tuple[Any, list[Diagnostic]]:
    """The tree with each valid `ros2:` stream wired to the generated node, and why any was not.

    An option or node that does not validate is left as it is: the composition's own schema reports it,
    located, and the stream (which then lacks a side) is set aside."""
    if not has_ros2(tree):
        return tree, []
    out, found = copy.deepcopy(tree), []
    try:
        system = Ros2System.model_validate(out.get("ros2") or {})
    except ValidationError:
        if "ros2" in out:
            return out, []  # reported by the schema, at `ros2`
        system = None
    publish, subscribe = {}, {}
    for name, entry in out["streams"].items():
        if not isinstance(entry, dict) or "ros2" not in entry:
            continue
        try:
            option = Ros2Stream.model_validate(entry["ros2"])
        except ValidationError:
            continue
        path = ("streams", name, "ros2")
        if system is None:
            found.append(Diagnostic("ros2-node", "a stream with 'ros2:' needs the system's ROS 2 node", path,
                                    hint="add a top-level 'ros2: {node: ..., connect: [tcp/HOST:7447]}'"))
            continue
        if option.distro not in (None, system.distro):
            found.append(Diagnostic("ros2-distro", f"distro '{option.distro}' is not the node's '{system.distro}'",
                                    path + ("distro",), hint="one node speaks one distribution: drop it or match"))
            continue
        spec = option.model_dump(mode="json", exclude={"distro"}, exclude_defaults=True)
        if "from" not in entry:
            subscribe[name] = spec
            entry["from"] = f"{ROS2}.{name}"
        elif not entry.get("to"):
            publish[name] = spec
            entry["to"] = [f"{ROS2}.{name}"]
        else:
            found.append(Diagnostic("ros2-sides", "a stream with 'ros2:' has one side in hapticop: 'from' (published "
                                    "to ROS 2) or 'to' (subscribed from it), not both", path,
                                    hint="split it: one stream to the readers, one with 'ros2:' and the same 'from'"))
    if not (publish or subscribe):
        return out, found
    for collection in ("activities", "threads"):
        if isinstance(out.get(collection), dict) and ROS2 in out[collection]:
            found.append(Diagnostic("ros2-name", f"'{ROS2}' is the name of the generated ROS 2 node's "
                                    f"{collection[:-1]}", (collection, ROS2), hint="rename this one"))
            return tree, found
    params = system.model_dump(mode="json", exclude={"period"}, exclude_defaults=True)
    out.setdefault("activities", {})[ROS2] = {
        "block": "ros2_bridge", "doc": "the streams with 'ros2:', as the ROS 2 node this system is (generated)",
        "params": {**params, **({"publish": publish} if publish else {}),
                   **({"subscribe": subscribe} if subscribe else {})}}
    out.setdefault("threads", {})[ROS2] = {
        "period": f"{system.period}ns", "deploy": "process", "schedules": {0: [ROS2]},
        "doc": "normal scheduling, its own process: Zenoh never shares a GIL with a real-time loop"}
    return out, found
