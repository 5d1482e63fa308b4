"""`hapticop graph`: one picture of deployment, dataflow and coordination.

Hosts are boxes holding their threads (network streams are bold purple arrows with their QoS),
threads are boxes holding their activities (labelled with the schedule IDs that run
them), streams are arrows between activities, dashed orange arrows join an activity to one it
needs (a device block to its simulator), each Petri net is a box of places (circles)
and transitions (bars), and flag-map bindings are dashed arrows between flags and places.
The DOT text needs nothing installed; SVG and PNG use graphviz's `dot` when it is on the
PATH, otherwise the pygraphviz wheel (`pip install hapticop[graph]`).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from hapticop.composition.description import Composition, Thread
from hapticop.composition.graph import CompositionGraph
from hapticop.composition.placement import Placement, place
from hapticop.composition.units import format_duration


class RenderError(RuntimeError):
    pass


def _by_host(comp: Composition) -> list[tuple[str, Thread]]:
    """The threads, each host's together (a host is a box around its threads' boxes)."""
    hosts = list(comp.hosts)
    return sorted(comp.threads.items(), key=lambda item: hosts.index(item[1].host) if item[1].host in hosts else -1)


def _first_of_host(comp: Composition, host: str) -> str | None:
    return next((name for name, t in _by_host(comp) if t.host == host), None)


def _last_of_host(comp: Composition, host: str) -> str | None:
    return next((name for name, t in reversed(_by_host(comp)) if t.host == host), None)


def _on_hosts(where: Placement | None, activity: str) -> int:
    return len(where.activity_hosts.get(activity, ())) if where is not None else 1


def _q(text: str) -> str:
    """Quote for DOT; a backslash stays, so label escapes such as \\n keep working."""
    return '"' + str(text).replace('"', '\\"') + '"'


def _id(*parts: object) -> str:
    return _q(":".join(str(p) for p in parts))


def to_dot(cg: CompositionGraph) -> str:
    comp = cg.loaded.composition
    lines = [
        f"digraph {_q(comp.name or 'composition')} {{",
        "  graph [rankdir=LR, fontname=Helvetica, compound=true, newrank=true];",
        "  node [fontname=Helvetica, fontsize=10];",
        "  edge [fontname=Helvetica, fontsize=9];",
    ]
    where = place(comp) if comp.hosts else None
    for tname, thread in _by_host(comp):
        if where is not None and thread.host in comp.hosts and tname == _first_of_host(comp, thread.host):
            spec = comp.hosts[thread.host]
            label = f"host {thread.host}\\n{', '.join(spec.endpoints)}"
            lines.append(f"  subgraph {_q('cluster_host_' + thread.host)} {{")
            lines.append(f"    label={_q(label)}; style=filled; fillcolor=aliceblue; color=gray40;")
        prio = f", FIFO {thread.priority}" if thread.priority else ""
        label = f"thread {tname}\\n{format_duration(thread.period)}{prio}, {thread.deploy}"
        lines.append(f"  subgraph {_q('cluster_thread_' + tname)} {{")
        lines.append(f"    label={_q(label)}; style=rounded; color=steelblue;")
        lines.append(f"    {_id('thread', tname)} [shape=point, style=invis];")
        placed = {}
        for sid, members in thread.schedules.items():
            for member in members:
                placed.setdefault(member, []).append(str(sid))
        for member, ids in placed.items():
            if member not in cg.loaded.activities:
                continue
            block = cg.loaded.activities[member].spec.block
            label = f"{member}\\n({block}) schedules {','.join(ids)}"
            node = _id('activity', member, thread.host) if _on_hosts(where, member) > 1 else _id('activity', member)
            lines.append(f"    {node} [shape=box, style=filled, fillcolor=lightyellow, label={_q(label)}];")
        lines.append("  }")
        if where is not None and thread.host in comp.hosts and tname == _last_of_host(comp, thread.host):
            lines.append("  }")
    for sname, stream in comp.streams.items():
        writer = stream.writer.split(".")
        for reader in stream.readers:
            reader_parts = reader.split(".")
            policy = stream.policy.kind + (f"[{stream.policy.capacity}]" if stream.policy.kind == "queue" else "")
            style = ""
            crosses = where is not None and where.port_host(reader) != where.port_host(stream.writer)
            if crosses and stream.network is not None:
                qos = stream.network
                deadline = format_duration(qos.deadline) if qos.deadline else "no deadline"
                policy = f"network {qos.priority}, {qos.keep}, {deadline}, stale {qos.stale}"
                style = ", color=purple, penwidth=2"
            lines.append(f"  {_id('activity', writer[0])} -> {_id('activity', reader_parts[0])} "
                         f"[label={_q(f'{sname}: {writer[1]}->{reader_parts[1]} ({policy})')}{style}];")
    for source, target, data in cg.edges_of("needs"):  # a device and its simulator, a simulator and its world
        lines.append(f"  {_id('activity', source[1])} -> {_id('activity', target[1])} [style=dashed, "
                     f"color=darkorange, label={_q('needs ' + data['need'].provides)}];")
    for nname, net in comp.coordination.nets.items():
        lines.append(f"  subgraph {_q('cluster_net_' + nname)} {{")
        lines.append(f"    label={_q('net ' + nname)}; style=dashed; color=gray40;")
        for pname in net.places:
            tokens = net.marking.get(pname, 0)
            label = pname + (f"\\n{'•' * tokens if tokens <= 3 else tokens}" if tokens else "")
            periph = 2 if pname in net.terminal else 1
            lines.append(f"    {_id('place', nname, pname)} [shape=circle, peripheries={periph}, fontsize=8, "
                         f"label={_q(label)}];")
        for tname, transition in net.transitions.items():
            lines.append(f"    {_id('transition', nname, tname)} [shape=box, style=filled, fillcolor=black, "
                         f"fontcolor=white, height=0.2, fontsize=8, label={_q(tname)}];")
            for pname, weight in transition.inputs.items():
                label = f" [label={weight}]" if weight != 1 else ""
                lines.append(f"    {_id('place', nname, pname)} -> {_id('transition', nname, tname)}{label};")
            for pname, weight in transition.outputs.items():
                label = f" [label={weight}]" if weight != 1 else ""
                lines.append(f"    {_id('transition', nname, tname)} -> {_id('place', nname, pname)}{label};")
            for pname in transition.inhibitors:  # an inhibitor arc ends in a small circle
                lines.append(f"    {_id('place', nname, pname)} -> {_id('transition', nname, tname)} "
                             "[arrowhead=odot];")
        lines.append("  }")
    for mname, fmap in comp.coordination.flag_maps.items():
        for kind in ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks"):
            style = "dashed" if kind.startswith("tracking") else "dotted"
            for flag_name, pname in getattr(fmap, kind).items():
                lines.append(f"  {_id('flag', flag_name)} [shape=note, fontsize=8, color=gray50, "
                             f"label={_q(flag_name)}];")
                ends = (_id("flag", flag_name), _id("place", fmap.net, pname))
                if kind.endswith("sinks"):
                    ends = ends[::-1]
                lines.append(f"  {ends[0]} -> {ends[1]} [style={style}, color=gray50, arrowsize=0.6];")
    lines.append("}")
    return "\n".join(lines) + "\n"


def render(dot_text: str, output: Path, fmt: str) -> None:
    """Write `dot_text` as `fmt` ('svg' or 'png') to `output`."""
    dot = shutil.which("dot")
    if dot:
        result = subprocess.run([dot, f"-T{fmt}", "-o", str(output)], input=dot_text.encode(), capture_output=True)
        if result.returncode != 0:
            raise RenderError(f"graphviz failed: {result.stderr.decode(errors='replace').strip()}")
        return
    try:
        import pygraphviz
    except ImportError:
        raise RenderError(
            "rendering needs graphviz: install the 'dot' program (apt-get install graphviz) or "
            "`pip install 'hapticop[graph]'`; `--format dot` writes the graph without it"
        ) from None
    try:
        pygraphviz.AGraph(string=dot_text).draw(str(output), format=fmt, prog="dot")
    except (OSError, ValueError) as error:
        raise RenderError(f"graphviz failed: {error}") from None
