"""A drawing as SVG without graphviz: a small layered (Sugiyama-style) layout, left to right.

Used by `hapticop graph` when neither graphviz's `dot` nor pygraphviz is installed. Cycles are
broken by reversing the edges a depth-first search finds going back; every node sits in an even
column after the longest path to it, and each edge passes a chain of dummy points through the
columns it crosses, the one in the middle carrying its label, so labels are laid out like nodes
and never overlap. The order within a column comes from a few barycentre sweeps, grouped by
cluster (a thread or a net), and a cluster is shown by its colour and a legend rather than a box.
"""

from __future__ import annotations

from dataclasses import dataclass
from html import escape

from hapticop.cli.drawing import Drawing, Edge

FONT = 12
CHAR_W = 0.6 * FONT
LINE_H = 1.3 * FONT
GAP_X, GAP_Y, MARGIN = 30.0, 16.0, 20.0
MAX_WIDTH = 2880  # px: a larger drawing is scaled down to this, as graphviz's size attribute does
PALETTE = ("#fff6cc", "#dcecfb", "#e2f5dc", "#fbe3e3", "#ece3fb", "#fbecd9", "#e0f4f4", "#f0f0f0")


@dataclass
class _Box:
    width: float
    height: float
    layer: int = 0
    x: float = 0.0
    y: float = 0.0  # centre


def _text_size(text: str, font: float = FONT) -> tuple[float, float]:
    lines = text.split("\n") if text else []
    return max((len(line) for line in lines), default=0) * 0.6 * font, len(lines) * 1.3 * font


def _node_box(label: str, shape: str) -> _Box:
    width, height = _text_size(label)
    if shape == "point":
        return _Box(6.0, 6.0)
    if shape == "circle":
        side = max(width, height) + 16
        return _Box(side, side)
    return _Box(width + 20, height + 12)


def to_svg(d: Drawing) -> str:
    edges = [e for e in d.edges if e.tail != e.head and e.tail in d.nodes and e.head in d.nodes]
    boxes = {nid: _node_box(node.label, node.shape) for nid, node in d.nodes.items()}
    forward = _acyclic(list(d.nodes), edges)
    _assign_layers(boxes, forward)
    chains = _chains(boxes, edges, forward)
    order = _order(boxes, chains, {nid: node.cluster for nid, node in d.nodes.items()})
    width, height = _place(boxes, order)

    colours = {cid: PALETTE[i % len(PALETTE)] for i, cid in enumerate(d.clusters)}
    legend_h = LINE_H * (len(d.clusters) + 1) + 10
    scale = min(1.0, MAX_WIDTH / width)
    out = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width * scale:.0f}" '
        f'height="{(height + legend_h) * scale:.0f}" '
        f'viewBox="0 0 {width:.0f} {height + legend_h:.0f}" font-family="Helvetica, Arial, sans-serif" '
        f'font-size="{FONT}">',
        "<defs>",
        '<marker id="normal" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="8" markerHeight="8" '
        'orient="auto"><path d="M0,0 L10,5 L0,10 z"/></marker>',
        '<marker id="odot" viewBox="0 0 10 10" refX="10" refY="5" markerWidth="8" markerHeight="8" '
        'orient="auto"><circle cx="5" cy="5" r="4" fill="white" stroke="black"/></marker>',
        "</defs>",
        '<rect width="100%" height="100%" fill="white"/>',
        f'<text x="{MARGIN}" y="{MARGIN + FONT}" font-weight="bold">{escape(d.title)}</text>',
    ]
    for i, (cid, label) in enumerate(d.clusters.items()):
        y = MARGIN + LINE_H * (i + 1) + 4
        out.append(f'<rect x="{MARGIN}" y="{y:.1f}" width="14" height="{FONT}" fill="{colours[cid]}" stroke="gray"/>'
                   f'<text x="{MARGIN + 20}" y="{y + FONT - 2:.1f}">{escape(label)}</text>')
    out.append(f'<g transform="translate(0,{legend_h:.1f})">')
    for edge, chain in chains:
        out.extend(_edge_svg(edge, chain, boxes))
    for nid, node in d.nodes.items():
        fill = colours.get(node.cluster, node.fill) if node.shape != "bar" else "black"
        out.extend(_node_svg(node.label, node.shape, boxes[nid], fill, node.peripheries))
    out.append("</g></svg>")
    return "\n".join(out) + "\n"


def _acyclic(nodes: list[str], edges: list[Edge]) -> set[tuple[str, str]]:
    """The edges kept in their direction: all but those a depth-first search finds going back."""
    successors: dict[str, list[str]] = {n: [] for n in nodes}
    for e in edges:
        successors[e.tail].append(e.head)
    state: dict[str, int] = {}  # 1 while on the search's path, 2 when finished
    back: set[tuple[str, str]] = set()
    for root in nodes:
        if root in state:
            continue
        state[root] = 1
        stack = [(root, iter(successors[root]))]
        while stack:
            node, pending = stack[-1]
            nxt = next(pending, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
            elif state.get(nxt) == 1:
                back.add((node, nxt))
            elif nxt not in state:
                state[nxt] = 1
                stack.append((nxt, iter(successors[nxt])))
    return {(e.tail, e.head) for e in edges if (e.tail, e.head) not in back}


def _assign_layers(boxes: dict[str, _Box], forward: set[tuple[str, str]]) -> None:
    """Every node two columns right of its furthest predecessor (the column between holds labels)."""
    predecessors: dict[str, list[str]] = {nid: [] for nid in boxes}
    for u, v in forward:
        predecessors[v].append(u)
    done: set[str] = set()

    def place(nid: str) -> int:
        stack = [nid]
        while stack:
            top = stack[-1]
            waiting = [p for p in predecessors[top] if p not in done]
            if waiting:
                stack.extend(waiting)
                continue
            stack.pop()
            if top not in done:
                boxes[top].layer = max((boxes[p].layer + 2 for p in predecessors[top]), default=0)
                done.add(top)
        return boxes[nid].layer

    for nid in list(boxes):
        place(nid)


def _chains(boxes: dict[str, _Box], edges: list[Edge], forward: set[tuple[str, str]]) -> list[tuple[Edge, list[str]]]:
    """Each edge as the node ids it passes through, left to right, with dummies in the columns between."""
    chains = []
    for i, edge in enumerate(edges):
        left, right = (edge.tail, edge.head) if (edge.tail, edge.head) in forward else (edge.head, edge.tail)
        a, b = boxes[left].layer, boxes[right].layer
        chain = [left]
        middle = (a + b) // 2 if (b - a) % 2 == 0 else a + 1
        for layer in range(a + 1, b):
            dummy = f"\0{i}:{layer}"
            w, h = _text_size(edge.label, FONT - 2) if layer == middle and edge.label else (0.0, 0.0)
            boxes[dummy] = _Box(w + 4, h + 4, layer)
            chain.append(dummy)
        chain.append(right)
        chains.append((edge, chain))
    return chains


def _order(boxes: dict[str, _Box], chains: list[tuple[Edge, list[str]]],
           clusters: dict[str, str | None]) -> list[list[str]]:
    """Columns of node ids, ordered by barycentre sweeps that keep a cluster's members together."""
    layers: dict[int, list[str]] = {}
    for nid, box in boxes.items():
        layers.setdefault(box.layer, []).append(nid)
    columns = [layers[k] for k in sorted(layers)]
    neighbours: dict[str, list[str]] = {nid: [] for nid in boxes}
    for _, chain in chains:
        for a, b in zip(chain, chain[1:]):
            neighbours[a].append(b)
            neighbours[b].append(a)
    rank = {nid: float(i) for column in columns for i, nid in enumerate(column)}
    for sweep in range(8):
        sequence = columns if sweep % 2 == 0 else columns[::-1]
        for column in sequence:
            def centre(nid: str) -> float:
                near = [rank[n] for n in neighbours[nid] if boxes[n].layer != boxes[nid].layer]
                return sum(near) / len(near) if near else rank[nid]
            centres = {nid: centre(nid) for nid in column}
            group: dict[str | None, list[float]] = {}
            for nid in column:
                group.setdefault(clusters.get(nid), []).append(centres[nid])
            column.sort(key=lambda n: (sum(group[clusters.get(n)]) / len(group[clusters.get(n)])
                                       if clusters.get(n) else centres[n], centres[n]))
            for i, nid in enumerate(column):
                rank[nid] = float(i)
    return columns


def _place(boxes: dict[str, _Box], columns: list[list[str]]) -> tuple[float, float]:
    heights = [sum(boxes[n].height for n in col) + GAP_Y * (len(col) - 1) for col in columns]
    total_h = max(heights, default=0.0)
    x = MARGIN
    for column, column_h in zip(columns, heights):
        width = max(boxes[n].width for n in column)
        y = MARGIN + (total_h - column_h) / 2
        for nid in column:
            box = boxes[nid]
            box.x, box.y = x + width / 2, y + box.height / 2
            y += box.height + GAP_Y
        x += width + GAP_X
    return x - GAP_X + MARGIN, total_h + 2 * MARGIN


def _edge_svg(edge: Edge, chain: list[str], boxes: dict[str, _Box]) -> list[str]:
    points = [(boxes[n].x, boxes[n].y) for n in chain]
    first, last = boxes[chain[0]], boxes[chain[-1]]
    points[0] = (first.x + first.width / 2, first.y)
    points[-1] = (last.x - last.width / 2, last.y)
    if edge.tail != chain[0]:  # laid out reversed: the arrow still points at its head
        points.reverse()
    dash = {"dashed": ' stroke-dasharray="6,3"', "dotted": ' stroke-dasharray="2,3"'}.get(edge.style, "")
    marker = f' marker-end="url(#{edge.arrowhead})"' if edge.arrowhead != "none" else ""
    path = " ".join(f"{x:.1f},{y:.1f}" for x, y in points)
    title = f"<title>{escape(edge.tooltip)}</title>" if edge.tooltip else ""
    out = [f'<polyline points="{path}" fill="none" stroke="{edge.color}"{dash}{marker}>{title}</polyline>']
    label_box = next((boxes[n] for n in chain[1:-1] if boxes[n].height > 4), None)
    if edge.label and label_box is not None:
        out.append(_text(edge.label, label_box.x, label_box.y, FONT - 2, edge.color))
    elif edge.label:  # no column between: beside the middle of the line
        (x0, y0), (x1, y1) = points[0], points[-1]
        out.append(_text(edge.label, (x0 + x1) / 2, (y0 + y1) / 2 - 6, FONT - 2, edge.color))
    return out


def _node_svg(label: str, shape: str, box: _Box, fill: str, peripheries: int) -> list[str]:
    left, top = box.x - box.width / 2, box.y - box.height / 2
    if shape == "point":
        return [f'<circle cx="{box.x:.1f}" cy="{box.y:.1f}" r="3" fill="black"/>']
    if shape == "circle":
        out = [f'<circle cx="{box.x:.1f}" cy="{box.y:.1f}" r="{box.width / 2 - 4 * i:.1f}" fill="{fill}" '
               'stroke="black"/>' for i in range(peripheries)]
        return [*out, _text(label, box.x, box.y, FONT)]
    radius = 0 if shape == "bar" else 6
    colour = "white" if shape == "bar" else "black"
    return [f'<rect x="{left:.1f}" y="{top:.1f}" width="{box.width:.1f}" height="{box.height:.1f}" '
            f'rx="{radius}" fill="{fill}" stroke="black"/>', _text(label, box.x, box.y, FONT, colour)]


def _text(label: str, x: float, y: float, font: float, colour: str = "black") -> str:
    lines = label.split("\n")
    top = y - (len(lines) - 1) * 1.3 * font / 2
    spans = "".join(f'<tspan x="{x:.1f}" y="{top + i * 1.3 * font + font * 0.35:.1f}">{escape(line)}</tspan>'
                    for i, line in enumerate(lines))
    return f'<text text-anchor="middle" font-size="{font:.0f}" fill="{colour}">{spans}</text>'
