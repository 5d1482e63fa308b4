"""`hapticop graph`: a composition drawn as one of a few views, each small enough to read.

The dataflow view (the default) shows threads as boxes holding their activities (labelled with the
schedule IDs that run them), streams as arrows labelled once with their name (a stream read by
several activities fans out from one junction), and dashed orange arrows from an activity to one it
needs (a device block to its simulator). The nets view draws each Petri net as a box of places
(circles) and transitions (bars), with the flags its flag maps bind; a net's name draws that net
alone; `all` draws everything in one picture. A view is first a `Drawing`, written as DOT for
graphviz (its `dot` program when on the PATH, else the pygraphviz wheel) or, with neither, as SVG
by the small layered layout in `hapticop.cli.layered`, drawn by `hapticop.cli.svg`.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from hapticop.cli.drawing import Drawing, Edge, Node
from hapticop.composition.graph import CompositionGraph
from hapticop.composition.placement import place
from hapticop.composition.units import format_duration, format_period

VIEWS = ("dataflow", "nets", "all")
MAX_SIZE_IN = 30  # a drawing larger than this (inches, 72 px each) is scaled down by graphviz


class RenderError(RuntimeError):
    pass


def views_of(cg: CompositionGraph) -> list[str]:
    return [*VIEWS, *cg.loaded.composition.coordination.nets]


def drawing(cg: CompositionGraph, view: str = "dataflow") -> Drawing:
    """The drawing of `view`: 'dataflow', 'nets', 'all', or the name of one net."""
    comp = cg.loaded.composition
    if view not in views_of(cg):
        raise RenderError(f"no view {view!r}: choose one of {', '.join(views_of(cg))}")
    d = Drawing(f"{comp.name or 'composition'} ({view})", aligned=view == "dataflow")
    if view in ("dataflow", "all"):
        _dataflow(cg, d)
    nets = list(comp.coordination.nets) if view in ("nets", "all") else [view] if view != "dataflow" else []
    for name in nets:
        _net(cg, name, d)
    return d


def _dataflow(cg: CompositionGraph, d: Drawing) -> None:
    comp = cg.loaded.composition
    for hname, host in comp.hosts.items():  # a host is a box around its threads' boxes
        d.clusters[f"host:{hname}"] = f"host {hname}: {', '.join(host.endpoints)}"
    for tname, thread in comp.threads.items():
        prio = f", FIFO {thread.priority}" if thread.priority else ""
        cluster = f"thread:{tname}"
        d.clusters[cluster] = f"thread {tname}: {format_period(thread.period)}{prio}, {thread.deploy}"
        if thread.host in comp.hosts:
            d.parents[cluster] = f"host:{thread.host}"
        placed: dict[str, list[str]] = {}
        for sid, members in thread.schedules.items():
            for member in members:
                placed.setdefault(member, []).append(str(sid))
        for member, ids in placed.items():
            if member in cg.loaded.activities and f"activity:{member}" not in d.nodes:
                block = cg.loaded.activities[member].spec.block
                d.nodes[f"activity:{member}"] = Node(f"{member}\n{block}\nschedules {','.join(ids)}",
                                                     cluster=cluster, fill="lightyellow")
    for name in cg.loaded.activities:  # never scheduled: drawn outside every thread
        d.nodes.setdefault(f"activity:{name}", Node(f"{name}\n{cg.loaded.activities[name].spec.block}"))
    where = place(comp) if comp.hosts else None
    for sname, stream in comp.streams.items():
        writer, writer_port = stream.writer.split(".", 1)
        policy = "" if stream.policy.kind == "latest" else f" (queue {stream.policy.capacity})"
        color = "black"
        if where is not None and sname in where.network:  # crosses hosts: its QoS on the arrow
            qos = stream.network
            deadline = format_duration(qos.deadline) if qos.deadline else "no deadline"
            policy = f" (network {qos.priority}, {qos.keep}, {deadline}, stale {qos.stale})"
            color = "purple"
        ports = ", ".join(f"{stream.writer} -> {reader}" for reader in stream.readers)
        tail = f"activity:{writer}"
        if len(stream.readers) > 1:  # one label, then a fan-out to every reader
            junction = f"stream:{sname}"
            d.nodes[junction] = Node("", shape="point")
            d.edges.append(Edge(tail, junction, sname + policy, color=color, tooltip=ports, arrowhead="none"))
            tail = junction
        for reader in stream.readers:
            label = "" if len(stream.readers) > 1 else sname + policy
            d.edges.append(Edge(tail, f"activity:{reader.split('.', 1)[0]}", label, color=color, tooltip=ports))
    for source, target, data in cg.edges_of("needs"):  # a device and its simulator, a simulator and its world
        d.edges.append(Edge(f"activity:{source[1]}", f"activity:{target[1]}", f"needs {data['need'].provides}",
                            style="dashed", color="darkorange"))


def _net(cg: CompositionGraph, nname: str, d: Drawing) -> None:
    comp = cg.loaded.composition
    net = comp.coordination.nets[nname]
    cluster = f"net:{nname}"
    d.clusters[cluster] = f"net {nname}"
    for pname in net.places:
        tokens = net.marking.get(pname, 0)
        label = pname + (f"\n{'•' * tokens if tokens <= 3 else tokens}" if tokens else "")
        d.nodes[f"place:{nname}:{pname}"] = Node(label, shape="circle", cluster=cluster,
                                                 peripheries=2 if pname in net.terminal else 1)
    for tname, transition in net.transitions.items():
        tid = f"transition:{nname}:{tname}"
        d.nodes[tid] = Node(tname, shape="bar", cluster=cluster)
        for pname, weight in transition.inputs.items():
            d.edges.append(Edge(f"place:{nname}:{pname}", tid, str(weight) if weight != 1 else ""))
        for pname, weight in transition.outputs.items():
            d.edges.append(Edge(tid, f"place:{nname}:{pname}", str(weight) if weight != 1 else ""))
        for pname in transition.inhibitors:
            d.edges.append(Edge(f"place:{nname}:{pname}", tid, arrowhead="odot"))
    for fmap in comp.coordination.flag_maps.values():
        if fmap.net != nname:
            continue
        for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
            for flag_name, pname in getattr(fmap, kind).items():
                d.nodes[f"flag:{flag_name}"] = Node(flag_name, shape="note", fill="whitesmoke")
                ends = (f"flag:{flag_name}", f"place:{nname}:{pname}")
                if kind.endswith("sinks"):
                    ends = ends[::-1]
                d.edges.append(Edge(*ends, style="dashed" if kind.startswith("tracking") else "dotted",
                                    color="#808080"))


def _q(text: str) -> str:
    """Quote for DOT, a line break written as graphviz's \\n."""
    return '"' + str(text).replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


_SHAPES = {
    "box": "shape=box, style=\"rounded,filled\"",
    "circle": "shape=ellipse, style=filled, fontsize=9, margin=\"0.04,0.02\"",
    "bar": "shape=box, style=filled, fillcolor=black, fontcolor=white, height=0.2, fontsize=9",
    "note": "shape=note, style=filled, fontsize=9",
    "point": "shape=point, width=0.08",
}


def to_dot(d: Drawing) -> str:
    lines = [
        f"digraph {_q(d.title)} {{",
        f'  graph [rankdir=LR, fontname=Helvetica, size="{MAX_SIZE_IN},{MAX_SIZE_IN}", '
        f"nodesep=0.3, ranksep=0.6{', newrank=true' if d.aligned else ''}];",
        "  node [fontname=Helvetica, fontsize=11];",
        "  edge [fontname=Helvetica, fontsize=9];",
    ]

    def node_line(nid: str, node: Node) -> str:
        fill = "" if node.shape in ("bar", "point") else f", fillcolor={_q(node.fill)}"
        rings = f", peripheries={node.peripheries}" if node.peripheries != 1 else ""
        return f"{_q(nid)} [{_SHAPES[node.shape]}{fill}{rings}, label={_q(node.label)}];"

    def cluster_lines(cid: str, indent: str) -> list[str]:
        style = "dashed" if cid.startswith("net:") else "rounded"
        inner = [child for child, parent in d.parents.items() if parent == cid]
        return [f"{indent}subgraph {_q('cluster_' + cid)} {{",
                f"{indent}  label={_q(d.clusters[cid])}; style={style}; color=steelblue;",
                *(f"{indent}  {node_line(nid, node)}" for nid, node in d.nodes.items() if node.cluster == cid),
                *(line for child in inner for line in cluster_lines(child, indent + "  ")),
                f"{indent}}}"]

    for cid in d.clusters:
        if cid not in d.parents:
            lines.extend(cluster_lines(cid, "  "))
    lines.extend(f"  {node_line(nid, node)}" for nid, node in d.nodes.items() if node.cluster is None)
    for edge in d.edges:
        attrs = [f"label={_q(edge.label)}"] if edge.label else []
        if edge.style != "solid":
            attrs.append(f"style={edge.style}")
        if edge.color != "black":
            attrs.append(f"color={_q(edge.color)}")
        if edge.arrowhead != "normal":
            attrs.append(f"arrowhead={edge.arrowhead}")
        if edge.tooltip:
            attrs.append(f"tooltip={_q(edge.tooltip)}")
        lines.append(f"  {_q(edge.tail)} -> {_q(edge.head)}" + (f" [{', '.join(attrs)}]" if attrs else "") + ";")
    lines.append("}")
    return "\n".join(lines) + "\n"


def renderer() -> str:
    """Which renderer `render` will use: 'dot', 'pygraphviz' or 'layered' (SVG only)."""
    if shutil.which("dot"):
        return "dot"
    try:
        import pygraphviz  # noqa: F401
    except ImportError:
        return "layered"
    return "pygraphviz"


def render(d: Drawing, output: Path, fmt: str) -> str:
    """Write `d` as `fmt` ('svg' or 'png') to `output`; return the renderer used."""
    used = renderer()
    if used == "dot":
        result = subprocess.run([shutil.which("dot"), f"-T{fmt}", "-o", str(output)], input=to_dot(d).encode(),
                                capture_output=True)
        if result.returncode != 0:
            raise RenderError(f"graphviz failed: {result.stderr.decode(errors='replace').strip()}")
    elif used == "pygraphviz":
        import pygraphviz

        try:
            pygraphviz.AGraph(string=to_dot(d)).draw(str(output), format=fmt, prog="dot")
        except (OSError, ValueError) as error:
            raise RenderError(f"graphviz failed: {error}") from None
    elif fmt == "svg":
        from hapticop.cli.svg import to_svg

        output.write_text(to_svg(d))
    else:
        raise RenderError(
            "a PNG needs graphviz: install the 'dot' program (apt-get install graphviz) or "
            "`pip install 'hapticop[graph]'`; SVG (the default) and `--format dot` need nothing"
        )
    return used
