"""The composition as one networkx graph: the single structure every check runs on.

Nodes are threads, activities, ports, streams, nets, places, transitions, flags, modes and
the parties that own flags; an activity that needs another (a device block and its simulator)
has a `needs` edge to it. Every reference written in the file becomes an edge that carries
the YAML path where it was written, so a check that finds a bad edge can say where. A
reference to something undeclared becomes a node with `declared=False` rather than an
exception, and the checks report it.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import networkx as nx

from hapticop.composition import flags as flagdefs
from hapticop.composition.loader import Loaded

Node = tuple


def thread(name: str) -> Node:
    return ("thread", name)


def activity(name: str) -> Node:
    return ("activity", name)


def port(activity_name: str, port_name: str) -> Node:
    return ("port", activity_name, port_name)


def stream(name: str) -> Node:
    return ("stream", name)


def net(name: str) -> Node:
    return ("net", name)


def place(net_name: str, place_name: str) -> Node:
    return ("place", net_name, place_name)


def transition(net_name: str, name: str) -> Node:
    return ("transition", net_name, name)


def mode(name: str) -> Node:
    return ("mode", name)


def flag(name: str) -> Node:
    return ("flag", name)


RUNTIME: Node = ("runtime",)


class CompositionGraph:
    """A MultiDiGraph plus the loaded composition it was built from."""

    def __init__(self, loaded: Loaded):
        self.loaded = loaded
        self.g = nx.MultiDiGraph()
        if loaded.composition is not None:
            self._build()

    # -- queries the checks use -------------------------------------------------------
    def nodes_of(self, kind: str, *, declared: bool | None = True) -> Iterator[tuple[Node, dict]]:
        for node, data in self.g.nodes(data=True):
            if node[0] == kind and (declared is None or data.get("declared", True) == declared):
                yield node, data

    def edges_of(self, kind: str) -> Iterator[tuple[Node, Node, dict]]:
        for u, v, data in self.g.edges(data=True):
            if data["kind"] == kind:
                yield u, v, data

    def threads_of(self, activity_name: str) -> set[str]:
        node = activity(activity_name)
        if node not in self.g:
            return set()
        return {u[1] for u, _, d in self.g.in_edges(node, data=True) if d["kind"] == "schedules"}

    # -- construction -----------------------------------------------------------------
    def _node(self, node: Node, **attrs: Any) -> None:
        if node in self.g and self.g.nodes[node].get("declared", True) and not attrs.get("declared", True):
            return  # a reference never downgrades a declaration
        self.g.add_node(node, **{"declared": True, **attrs})

    def _reference(self, node: Node, collection: str, name: str) -> bool:
        """Make sure a referenced node exists; False if it belongs to a set-aside entry."""
        if self.loaded.is_broken(collection, name):
            return False
        if node not in self.g:
            self.g.add_node(node, declared=False)
        return True

    def _build(self) -> None:
        comp = self.loaded.composition
        self._node(RUNTIME, path=())
        for name, flag_info in flagdefs.system_flags().items():
            self._flag(flag_info, RUNTIME)

        for name, spec in comp.threads.items():
            self._node(thread(name), spec=spec, path=("threads", name))
            for info in flagdefs.thread_flags(name, sorted(spec.schedules)).values():
                self._flag(info, thread(name))

        for name, spec in comp.activities.items():
            if name not in self.loaded.activities:
                continue
            resolved = self.loaded.activities[name]
            self._node(activity(name), spec=spec, resolved=resolved, path=("activities", name))
            iface = resolved.interface
            for direction, ports in (("output", iface.outputs), ("input", iface.inputs)):
                for pname, pspec in ports.items():
                    self._node(port(name, pname), port=pspec, direction=direction, path=("activities", name))
                    self.g.add_edge(activity(name), port(name, pname), kind="has_port", path=("activities", name))
            flag_set = flagdefs.activity_flags(name, iface.flags_written, iface.flags_read)
            for info in flag_set.values():
                self._flag(info, activity(name))

        for name, resolved in self.loaded.activities.items():
            for need in resolved.interface.needs:
                if self._reference(activity(need.activity), "activities", need.activity):
                    self.g.add_edge(activity(name), activity(need.activity), kind="needs", need=need,
                                    path=("activities", name, "params", need.param))

        for name, spec in comp.threads.items():
            for sid, members in spec.schedules.items():
                for index, member in enumerate(members):
                    if self._reference(activity(member), "activities", member):
                        self.g.add_edge(
                            thread(name), activity(member), kind="schedules", schedule=sid,
                            path=("threads", name, "schedules", sid, index),
                        )

        for name, spec in comp.streams.items():
            self._node(stream(name), spec=spec, path=("streams", name))
            writer_activity, writer_port = spec.writer.split(".")
            if self._port_reference(writer_activity, writer_port):
                self.g.add_edge(port(writer_activity, writer_port), stream(name), kind="writes",
                                path=("streams", name, "from"))
            for index, reader in enumerate(spec.readers):
                reader_activity, reader_port = reader.split(".")
                if self._port_reference(reader_activity, reader_port):
                    self.g.add_edge(stream(name), port(reader_activity, reader_port), kind="reads",
                                    path=("streams", name, "to", index))

        for name in comp.coordination.flags:
            for info in flagdefs.coupling_flags([name]).values():
                self._node(flag(info.name), info=info, path=("coordination", "flags", name))

        for name, spec in comp.coordination.nets.items():
            base = ("coordination", "nets", name)
            self._node(net(name), spec=spec, path=base)
            for pname in spec.places:
                self._node(place(name, pname), path=base + ("places", pname))
                self.g.add_edge(net(name), place(name, pname), kind="contains", path=base + ("places", pname))
            for tname, tspec in spec.transitions.items():
                tpath = base + ("transitions", tname)
                self._node(transition(name, tname), spec=tspec, path=tpath)
                self.g.add_edge(net(name), transition(name, tname), kind="contains", path=tpath)
                for pname, weight in tspec.inputs.items():
                    self._node(place(name, pname), declared=False)
                    self.g.add_edge(place(name, pname), transition(name, tname), kind="arc", weight=weight,
                                    path=tpath + ("in", pname))
                for pname, weight in tspec.outputs.items():
                    self._node(place(name, pname), declared=False)
                    self.g.add_edge(transition(name, tname), place(name, pname), kind="arc", weight=weight,
                                    path=tpath + ("out", pname))
                for index, pname in enumerate(tspec.inhibitors):
                    self._node(place(name, pname), declared=False)
                    if not self.g.has_edge(place(name, pname), transition(name, tname)):
                        self.g.add_edge(place(name, pname), transition(name, tname), kind="inhibitor",
                                        path=tpath + ("unless", index))
            for field_name in ("marking", "terminal"):
                for index, pname in enumerate(getattr(spec, field_name)):
                    self._node(place(name, pname), declared=False)
                    key = pname if field_name == "marking" else index
                    self.g.add_edge(net(name), place(name, pname), kind=field_name, path=base + (field_name, key))

        for name, spec in comp.coordination.flag_maps.items():
            base = ("coordination", "flag_maps", name)
            if not self._reference(net(spec.net), "coordination.nets", spec.net):
                continue
            if self.g.nodes[net(spec.net)].get("declared", True) is False:
                self.g.add_node(net(spec.net), declared=False, referenced_at=base + ("net",))
            for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
                for flag_name, pname in getattr(spec, kind).items():
                    path = base + (kind, flag_name)
                    if flag(flag_name) not in self.g:
                        self.g.add_node(flag(flag_name), declared=False)
                    self._node(place(spec.net, pname), declared=False)
                    if kind.endswith("sources"):
                        self.g.add_edge(flag(flag_name), place(spec.net, pname), kind="source", mode=kind,
                                        flag_map=name, path=path)
                    else:
                        self.g.add_edge(place(spec.net, pname), flag(flag_name), kind="sink", mode=kind,
                                        flag_map=name, path=path)

        for name, spec in comp.modes.items():  # a mode reads its flag like a tracking source
            path = ("modes", name)
            self._node(mode(name), spec=spec, path=path)
            if flag(spec.when) not in self.g:
                self.g.add_node(flag(spec.when), declared=False)
            self.g.add_edge(flag(spec.when), mode(name), kind="source", mode="mode", path=path + ("when",))

    def _port_reference(self, activity_name: str, port_name: str) -> bool:
        if not self._reference(activity(activity_name), "activities", activity_name):
            return False
        if port(activity_name, port_name) not in self.g:
            self.g.add_node(port(activity_name, port_name), declared=False)
        return True

    def _flag(self, info: flagdefs.FlagInfo, owner: Node) -> None:
        self._node(flag(info.name), info=info, path=self.g.nodes[owner].get("path", ()))
        if info.writers:
            self.g.add_edge(owner, flag(info.name), kind="owns_write", path=())
        if info.readers:
            self.g.add_edge(flag(info.name), owner, kind="owns_read", path=())
