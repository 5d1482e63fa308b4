"""Streams that ROS 2 sees: a stream's `ros2:` option, and the ROS 2 node the loader writes for them.

A stream with `ros2:` and no `to:` is published to ROS 2; one with `ros2:` and no `from:` is subscribed
from it. The user writes no bridge: like the hosts' split (placement.py), `expand` rewrites the YAML tree
so that these streams end or start at a generated `ros2_bridge` activity (`ros2`) on a thread of its own
in its own process, configured by the system's `ros2:` node (docs/ros2.md). The tree's nodes are kept, so
findings on the streams stay located in the file.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from pydantic import Field, ValidationError

from hapticop.composition.diagnostics import Diagnostic
from hapticop.composition.units import Duration
from hapticop.ros2 import names
from hapticop.ros2.messages import LAYOUTS, layout_of
from hapticop.ros2.topics import Ros2Node, Ros2Topic

ROS2 = "ros2"
"""The generated node's activity and thread."""
HOSTS_BRIDGE = "bridge"  # placement.BRIDGE: the hosts' bridge (placement imports the description, which imports this)
GENERATED = "the streams with 'ros2:', as the ROS 2 node this system is (generated)"
"""The generated activity's doc, by which a tree already rewritten (a host's share of one) is known."""


class Ros2Stream(Ros2Topic):
    """A stream's ROS 2 topic: published when the stream has no `to:`, subscribed when it has no `from:`."""

    distro: names.Distro | None = Field(None, description="the distribution, if said here: it must be the "
                                        "system's (`ros2: {distro: ...}`), one node speaking one distribution")


class Ros2System(Ros2Node):
    """The ROS 2 node that carries the composition's `ros2:` streams."""

    period: Duration = Field(5_000_000, description="the node's cycle (topics are published at their own "
                             "rates, taken each cycle)")
    host: str | None = Field(None, description="with 'hosts:', the host the node runs on; a stream between it "
                             "and a port on another host crosses the link like any other (it needs 'network:')")


def has_ros2(tree: Any) -> bool:
    """Streams with `ros2:`, or the system's node publishing the run's flags."""
    if not isinstance(tree, dict):
        return False
    streams, node = tree.get("streams"), tree.get("ros2")
    return (isinstance(streams, dict) and any(isinstance(e, dict) and "ros2" in e for e in streams.values())) or (
        isinstance(node, dict) and node.get("flags") is not None)


PortOf = Callable[[dict, str], Any]
"""The port an `activity.port` reference names in a tree, from its block's declaration (the loader's), or None."""


def _infer_shape(tree: dict, entry: dict, port_of: PortOf) -> None:
    """A `ros2:` option without `shape` takes it from the hapticop port it carries, when that port fits one of
    the message's layouts (a scan's length, a planar or a full twist): the port is the reference."""
    option = entry.get("ros2")
    if not isinstance(option, dict) or "shape" in option or option.get("type") not in LAYOUTS:
        return
    for ref in [entry.get("from"), *(entry.get("to") or [])]:
        port = port_of(tree, ref) if isinstance(ref, str) and not ref.startswith(f"{ROS2}.") else None
        if port is not None and layout_of(option["type"], port.dtype, tuple(port.shape)) is not None:
            option["shape"] = list(port.shape)
            return


def _across_hosts(entry: dict) -> bool:
    """In a host's share (`placement.for_host`), the stream runs between a local port and the hosts' bridge:
    its ROS 2 side is the node's, on another host."""
    sides = [entry.get("from"), *(entry.get("to") or [])]
    return "from" in entry and bool(entry.get("to")) and any(
        isinstance(side, str) and side.startswith(f"{HOSTS_BRIDGE}.") for side in sides)


def expand(tree: Any, port_of: PortOf | None = None) -> tuple[Any, list[Diagnostic]]:
    """The tree with each valid `ros2:` stream wired to the generated node, and why any was not.

    An option or node that does not validate is left as it is: the composition's own schema reports it,
    located, and the stream (which then lacks a side) is set aside."""
    if not has_ros2(tree):
        return tree, []
    activities = tree.get("activities")
    if isinstance(activities, dict) and isinstance(activities.get(ROS2), dict) and (
            activities[ROS2].get("doc") == GENERATED):
        return tree, []  # rewritten already: a host's share of a composition with 'hosts:' is loaded again
    out, found = copy.deepcopy(tree), []
    try:
        system = Ros2System.model_validate(out.get("ros2") or {})
    except ValidationError:
        if "ros2" in out:
            return out, []  # reported by the schema, at `ros2`
        system = None
    publish, subscribe = {}, {}
    for name, entry in (out.get("streams") or {}).items():
        if not isinstance(entry, dict) or "ros2" not in entry:
            continue
        if port_of is not None:
            _infer_shape(out, entry, port_of)
        try:
            option = Ros2Stream.model_validate(entry["ros2"])
        except ValidationError:
            continue
        if _across_hosts(entry) and f"{ROS2}.{name}" not in [entry.get("from"), *(entry.get("to") or [])]:
            continue  # a host's share of a composition with 'hosts:': the node is on another host, over the link
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
        if entry.get("from") == f"{ROS2}.{name}":  # wired already, to a host's bridge (placement.for_host)
            subscribe[name] = spec
        elif f"{ROS2}.{name}" in (entry.get("to") or []):
            publish[name] = spec
        elif "from" not in entry:
            subscribe[name] = spec
            entry["from"] = f"{ROS2}.{name}"
        elif not entry.get("to"):
            publish[name] = spec
            entry["to"] = [f"{ROS2}.{name}"]
        else:
            found.append(Diagnostic("ros2-sides", "a stream with 'ros2:' has one side in hapticop: 'from' (published "
                                    "to ROS 2) or 'to' (subscribed from it), not both", path,
                                    hint="split it: one stream to the readers, one with 'ros2:' and the same 'from'"))
    if not (publish or subscribe or (system is not None and system.flags is not None)):
        return out, found
    for collection in ("activities", "threads"):
        if isinstance(out.get(collection), dict) and ROS2 in out[collection]:
            found.append(Diagnostic("ros2-name", f"'{ROS2}' is the name of the generated ROS 2 node's "
                                    f"{collection[:-1]}", (collection, ROS2), hint="rename this one"))
            return tree, found
    if isinstance(out.get("hosts"), dict) and system.host is None:
        found.append(Diagnostic("ros2-host", "with 'hosts:', the ROS 2 node runs on one of them: it names none",
                                ("ros2",), hint=f"add 'host:' ({', '.join(map(str, out['hosts']))})"))
    params = system.model_dump(mode="json", exclude={"period", "host"}, exclude_defaults=True)
    out.setdefault("activities", {})[ROS2] = {
        "block": "ros2_bridge", "doc": GENERATED,
        "params": {**params, **({"publish": publish} if publish else {}),
                   **({"subscribe": subscribe} if subscribe else {})}}
    out.setdefault("threads", {})[ROS2] = {
        "period": f"{system.period}ns", "deploy": "process", "schedules": {0: [ROS2]},
        "doc": "normal scheduling, its own process: Zenoh never shares a GIL with a real-time loop",
        **({"host": system.host} if system.host is not None else {})}
    return out, found
