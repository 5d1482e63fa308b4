"""A drawing as SVG without graphviz: a small layered (Sugiyama-style) layout.

Used by `hapticop graph` when neither graphviz's `dot` nor pygraphviz is installed. Each connected
part of the drawing is laid out alone: cycles are broken by reversing the edges a depth-first
search finds going back; every node sits in an even layer after the longest path to it, and each
edge passes a chain of dummy points through the layers it crosses, the one in the middle carrying
its label, so labels are laid out like nodes and never overlap. The order within a layer comes from
barycentre sweeps grouped by cluster (a thread or a net), the sweep with fewest crossings kept and
then neighbours exchanged while that removes crossings; boxes then move across their layer towards
their neighbours so edges run straight. A part is laid out top to bottom or left to right, whichever
is nearer a screen's shape, and the parts are packed in rows to about that shape (the hallway's
dataflow was a 2634 x 428 px strip). A cluster is shown by its colour and a legend, not a box.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

from hapticop.cli.drawing import Drawing, Edge

FONT = 12
CHAR_W = 0.6 * FONT
LINE_H = 1.3 * FONT
GAP_X, GAP_Y, MARGIN = 30.0, 16.0, 20.0
ASPECT = 1.6  # width to height the layout aims for: a screen's
SWEEPS = 24  # barycentre sweeps, alternately down and up the layers
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


@dataclass
class Layout:
    """Where everything of a drawing goes: its boxes (nodes, and the points edges pass through),
    each edge's chain of them, the layers of every part in order, and the picture's size."""

    boxes: dict[str, _Box]
    chains: list[tuple[Edge, list[str]]]
    columns: list[list[str]]  # each part's layers, one after the other
    vertical: set[str]  # the nodes of parts laid out top to bottom (the others: left to right)
    width: float
    height: float


def layout(d: Drawing) -> Layout:
    """Each connected part laid out in layers, top to bottom or left to right (whichever is nearer
    the screen's shape), then the parts packed in rows to about that shape."""
    edges = [e for e in d.edges if e.tail != e.head and e.tail in d.nodes and e.head in d.nodes]
    boxes = {nid: _node_box(node.label, node.shape) for nid, node in d.nodes.items()}
    clusters = {nid: node.cluster for nid, node in d.nodes.items()}
    chains: list[tuple[Edge, list[str]]] = []
    columns: list[list[str]] = []
    vertical: set[str] = set()
    parts: list[tuple[list[str], float, float]] = []
    for members in _parts(list(d.nodes), edges):
        inside = set(members)
        numbered = [(i, e) for i, e in enumerate(edges) if e.tail in inside]
        forward = _acyclic(members, [e for _, e in numbered])
        part = {nid: boxes[nid] for nid in members}
        _assign_layers(part, forward)
        part_chains = _chains(part, numbered, forward)
        boxes.update(part)
        order = _order(part, part_chains, clusters)
        across = _place(part, order, vertical=False)
        down = _place(part, order, vertical=True)
        upright = abs(math.log(down[0] / down[1] / ASPECT)) < abs(math.log(across[0] / across[1] / ASPECT))
        _place(part, order, vertical=upright)
        width, height = _straighten(part, order, _neighbours(part, part_chains), upright)
        if upright:
            vertical.update(part)
        chains += part_chains
        columns += order
        parts.append((list(part), width, height))
    width, height = _pack(boxes, parts)
    return Layout(boxes, chains, columns, vertical, width, height)


def _parts(nodes: list[str], edges: list[Edge]) -> list[list[str]]:
    """The drawing's connected parts (edges taken both ways), each in the drawing's order, largest first."""
    neighbours: dict[str, list[str]] = {n: [] for n in nodes}
    for e in edges:
        neighbours[e.tail].append(e.head)
        neighbours[e.head].append(e.tail)
    seen: set[str] = set()
    parts = []
    for root in nodes:
        if root in seen:
            continue
        seen.add(root)
        found, stack = {root}, [root]
        while stack:
            for nxt in neighbours[stack.pop()]:
                if nxt not in seen:
                    seen.add(nxt)
                    found.add(nxt)
                    stack.append(nxt)
        parts.append([n for n in nodes if n in found])
    return sorted(parts, key=len, reverse=True)


def _pack(boxes: dict[str, _Box], parts: list[tuple[list[str], float, float]]) -> tuple[float, float]:
    """The parts in rows (each laid out from the origin), tallest first, rows about as wide as
    the whole is to be: its area at the screen's shape, or the widest part."""
    area = sum(w * h for _, w, h in parts)
    row_width = max(max((w for _, w, _ in parts), default=0.0), math.sqrt(area * ASPECT))
    x = y = row_height = width = 0.0
    for members, w, h in sorted(parts, key=lambda p: p[2], reverse=True):
        if x > 0 and x + w > row_width:
            x, y, row_height = 0.0, y + row_height, 0.0
        for nid in members:
            boxes[nid].x += x
            boxes[nid].y += y
        x += w
        width, row_height = max(width, x), max(row_height, h)
    return width, y + row_height


def crossings(laid: Layout) -> int:
    """How many pairs of edge segments cross between neighbouring layers."""
    return _crossings(laid.columns, [chain for _, chain in laid.chains])


def _crossings(columns: list[list[str]], chains: list[list[str]]) -> int:
    column_of = {nid: c for c, column in enumerate(columns) for nid in column}
    position = {nid: i for column in columns for i, nid in enumerate(column)}
    between: dict[int, list[tuple[int, int]]] = {}
    for chain in chains:
        for a, b in zip(chain, chain[1:]):
            if column_of[a] > column_of[b]:
                a, b = b, a
            between.setdefault(column_of[a], []).append((position[a], position[b]))
    count = 0
    for segments in between.values():
        for i, (a1, b1) in enumerate(segments):
            for a2, b2 in segments[i + 1:]:
                count += (a1 - a2) * (b1 - b2) < 0
    return count


def to_svg(d: Drawing) -> str:
    laid = layout(d)
    boxes, chains, width, height = laid.boxes, laid.chains, laid.width, laid.height

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
        out.extend(_edge_svg(edge, chain, boxes, chain[0] in laid.vertical))
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


def _chains(boxes: dict[str, _Box], edges: list[tuple[int, Edge]],
            forward: set[tuple[str, str]]) -> list[tuple[Edge, list[str]]]:
    """Each edge (numbered) as the node ids it passes through, layer by layer, with dummies in the layers between."""
    chains = []
    for i, edge in edges:
        left, right = (edge.tail, edge.head) if (edge.tail, edge.head) in forward else (edge.head, edge.tail)
        a, b = boxes[left].layer, boxes[right].layer
        chain = [left]
        middle = (a + b) // 2 if (b - a) % 2 == 0 else a + 1
        for layer in range(a + 1, b):
            dummy = f"\0{i}:{layer}"
            w, h = _text_size(_wrapped(edge.label), FONT - 2) if layer == middle and edge.label else (0.0, 0.0)
            boxes[dummy] = _Box(w + 4, h + 4, layer)
            chain.append(dummy)
        chain.append(right)
        chains.append((edge, chain))
    return chains


def _neighbours(boxes: dict[str, _Box], chains: list[tuple[Edge, list[str]]]) -> dict[str, list[str]]:
    found: dict[str, list[str]] = {nid: [] for nid in boxes}
    for _, chain in chains:
        for a, b in zip(chain, chain[1:]):
            found[a].append(b)
            found[b].append(a)
    return found


def _order(boxes: dict[str, _Box], chains: list[tuple[Edge, list[str]]],
           clusters: dict[str, str | None]) -> list[list[str]]:
    """Layers of node ids, ordered by barycentre sweeps that keep a cluster's members together, then
    neighbours exchanged where that removes crossings; the order with fewest crossings seen is kept."""
    layers: dict[int, list[str]] = {}
    for nid, box in boxes.items():
        layers.setdefault(box.layer, []).append(nid)
    columns = [layers[k] for k in sorted(layers)]
    neighbours = _neighbours(boxes, chains)
    paths = [chain for _, chain in chains]
    rank = {nid: float(i) for column in columns for i, nid in enumerate(column)}
    best, fewest = [list(c) for c in columns], _crossings(columns, paths)
    for sweep in range(SWEEPS):
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
        count = _crossings(columns, paths)
        if count < fewest:
            best, fewest = [list(c) for c in columns], count
    _exchange(best, paths, clusters, fewest)
    return best


def _exchange(columns: list[list[str]], paths: list[list[str]], clusters: dict[str, str | None], count: int) -> None:
    """Swap neighbours within a layer (of one cluster, or of none) while a swap removes crossings,
    counting only the crossings on either side of that layer."""
    column_of = {nid: c for c, column in enumerate(columns) for nid in column}
    segments: dict[int, list[tuple[str, str]]] = {}  # between layer k and k + 1
    for path in paths:
        for a, b in zip(path, path[1:]):
            if column_of[a] > column_of[b]:
                a, b = b, a
            segments.setdefault(column_of[a], []).append((a, b))
    position = {nid: i for column in columns for i, nid in enumerate(column)}

    def near(c: int) -> int:
        total = 0
        for k in (c - 1, c):
            pairs = [(position[a], position[b]) for a, b in segments.get(k, ())]
            total += sum((a1 - a2) * (b1 - b2) < 0 for i, (a1, b1) in enumerate(pairs) for a2, b2 in pairs[i + 1:])
        return total

    improved = True
    while improved and count:
        improved = False
        for c, column in enumerate(columns):
            for i in range(len(column) - 1):
                first, second = column[i], column[i + 1]
                if clusters.get(first) != clusters.get(second):
                    continue
                before = near(c)
                position[first], position[second] = i + 1, i
                after = near(c)
                if after < before:
                    column[i], column[i + 1] = second, first
                    count, improved = count - (before - after), True
                else:
                    position[first], position[second] = i, i + 1


def _place(boxes: dict[str, _Box], columns: list[list[str]], vertical: bool) -> tuple[float, float]:
    """Centres for every box, layer after layer from the origin, left to right or (`vertical`) top
    to bottom, each layer centred across; returns the size, margins included."""
    along = [max(boxes[n].height if vertical else boxes[n].width for n in col) for col in columns]
    across = [sum(boxes[n].width if vertical else boxes[n].height for n in col) +
              (GAP_X if vertical else GAP_Y) * (len(col) - 1) for col in columns]
    gap_along = GAP_Y * 1.5 if vertical else GAP_X
    total = max(across, default=0.0)
    at = MARGIN
    for column, size, extent in zip(columns, along, across):
        side = MARGIN + (total - extent) / 2
        for nid in column:
            box = boxes[nid]
            if vertical:
                box.x, box.y = side + box.width / 2, at + size / 2
                side += box.width + GAP_X
            else:
                box.x, box.y = at + size / 2, side + box.height / 2
                side += box.height + GAP_Y
        at += size + gap_along
    length = at - gap_along + MARGIN
    return (total + 2 * MARGIN, length) if vertical else (length, total + 2 * MARGIN)


def _straighten(boxes: dict[str, _Box], columns: list[list[str]], neighbours: dict[str, list[str]],
                vertical: bool) -> tuple[float, float]:
    """Move boxes across their layer towards the middle of their neighbours in the layer before
    (sweeping down, then up), keeping the order and the gaps: an edge runs as straight as its
    layer lets it. Each layer is placed pushed from the left and from the right, and the two
    averaged, which keeps every gap. Returns the size, margins included."""
    across = "x" if vertical else "y"
    size = (lambda b: b.width) if vertical else (lambda b: b.height)
    gap = GAP_X if vertical else GAP_Y
    index = {nid: c for c, column in enumerate(columns) for nid in column}
    for sweep in range(4):
        step = 1 if sweep % 2 == 0 else -1
        for c in (range(1, len(columns)) if step == 1 else range(len(columns) - 2, -1, -1)):
            column = columns[c]
            wanted = []
            for nid in column:
                near = [getattr(boxes[n], across) for n in neighbours[nid] if index[n] == c - step]
                wanted.append(sum(near) / len(near) if near else getattr(boxes[nid], across))
            left, right = list(wanted), list(wanted)
            for i in range(1, len(column)):
                least = left[i - 1] + (size(boxes[column[i - 1]]) + size(boxes[column[i]])) / 2 + gap
                left[i] = max(left[i], least)
            for i in range(len(column) - 2, -1, -1):
                most = right[i + 1] - (size(boxes[column[i + 1]]) + size(boxes[column[i]])) / 2 - gap
                right[i] = min(right[i], most)
            for nid, a, b in zip(column, left, right):
                setattr(boxes[nid], across, (a + b) / 2)
    low = min(getattr(b, across) - size(b) / 2 for b in boxes.values())
    high = max(getattr(b, across) + size(b) / 2 for b in boxes.values())
    for box in boxes.values():
        setattr(box, across, getattr(box, across) - low + MARGIN)
    extent = high - low + 2 * MARGIN
    along = max((b.y + b.height / 2) if vertical else (b.x + b.width / 2) for b in boxes.values()) + MARGIN
    return (extent, along) if vertical else (along, extent)


def _edge_svg(edge: Edge, chain: list[str], boxes: dict[str, _Box], vertical: bool) -> list[str]:
    points = [(boxes[n].x, boxes[n].y) for n in chain]
    first, last = boxes[chain[0]], boxes[chain[-1]]
    if vertical:  # from the bottom of one box to the top of the next layer's
        points[0] = (first.x, first.y + first.height / 2)
        points[-1] = (last.x, last.y - last.height / 2)
    else:
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
        out.append(_text(_wrapped(edge.label), label_box.x, label_box.y, FONT - 2, edge.color))
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


def _wrapped(label: str) -> str:
    """An edge's label with what it says of the stream in brackets on a line of its own (a network
    stream's QoS is longer than its name)."""
    return label.replace(" (", "\n(", 1)


def _text(label: str, x: float, y: float, font: float, colour: str = "black") -> str:
    lines = label.split("\n")
    top = y - (len(lines) - 1) * 1.3 * font / 2
    spans = "".join(f'<tspan x="{x:.1f}" y="{top + i * 1.3 * font + font * 0.35:.1f}">{escape(line)}</tspan>'
                    for i, line in enumerate(lines))
    return f'<text text-anchor="middle" font-size="{font:.0f}" fill="{colour}">{spans}</text>'
