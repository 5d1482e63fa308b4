"""A drawing laid out without graphviz: a small layered (Sugiyama-style) layout.

Used by `hapticop graph` when neither graphviz's `dot` nor pygraphviz is installed. Each connected
part of the drawing is laid out alone: cycles are broken by reversing the edges a depth-first
search finds going back; every node sits in an even layer after the longest path to it, and each
edge passes a chain of dummy points through the layers it crosses, the one in the middle carrying
its label, so labels are laid out like nodes and never overlap. The order within a layer comes from
barycentre sweeps grouped by cluster (a thread or a net), the sweep with fewest crossings kept and
then neighbours exchanged while that removes crossings; boxes then move across their layer towards
their neighbours so edges run straight. A part is laid out top to bottom or left to right, whichever
is nearer a screen's shape, and the parts are packed in rows to about that shape (the hallway's
dataflow was a 2634 x 428 px strip). `svg.py` draws the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hapticop.cli.drawing import Drawing, Edge

FONT = 12
CHAR_W = 0.6 * FONT
LINE_H = 1.3 * FONT
GAP_X, GAP_Y, MARGIN = 30.0, 16.0, 20.0
ASPECT = 1.6  # width to height the layout aims for: a screen's
SWEEPS = 24  # barycentre sweeps, alternately down and up the layers


@dataclass
class Box:
    width: float
    height: float
    layer: int = 0
    x: float = 0.0
    y: float = 0.0  # centre


def _text_size(text: str, font: float = FONT) -> tuple[float, float]:
    lines = text.split("\n") if text else []
    return max((len(line) for line in lines), default=0) * 0.6 * font, len(lines) * 1.3 * font


def _node_box(label: str, shape: str) -> Box:
    width, height = _text_size(label)
    if shape == "point":
        return Box(6.0, 6.0)
    if shape == "circle":
        side = max(width, height) + 16
        return Box(side, side)
    return Box(width + 20, height + 12)


@dataclass
class Layout:
    """Where everything of a drawing goes: its boxes (nodes, and the points edges pass through),
    each edge's chain of them, the layers of every part in order, and the picture's size."""

    boxes: dict[str, Box]
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


def _pack(boxes: dict[str, Box], parts: list[tuple[list[str], float, float]]) -> tuple[float, float]:
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


def _assign_layers(boxes: dict[str, Box], forward: set[tuple[str, str]]) -> None:
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


def _chains(boxes: dict[str, Box], edges: list[tuple[int, Edge]],
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
            w, h = _text_size(wrapped(edge.label), FONT - 2) if layer == middle and edge.label else (0.0, 0.0)
            boxes[dummy] = Box(w + 4, h + 4, layer)
            chain.append(dummy)
        chain.append(right)
        chains.append((edge, chain))
    return chains


def _neighbours(boxes: dict[str, Box], chains: list[tuple[Edge, list[str]]]) -> dict[str, list[str]]:
    found: dict[str, list[str]] = {nid: [] for nid in boxes}
    for _, chain in chains:
        for a, b in zip(chain, chain[1:]):
            found[a].append(b)
            found[b].append(a)
    return found


def _order(boxes: dict[str, Box], chains: list[tuple[Edge, list[str]]],
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


def _place(boxes: dict[str, Box], columns: list[list[str]], vertical: bool) -> tuple[float, float]:
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


def _straighten(boxes: dict[str, Box], columns: list[list[str]], neighbours: dict[str, list[str]],
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


def wrapped(label: str) -> str:
    """An edge's label with what it says of the stream in brackets on a line of its own (a network
    stream's QoS is longer than its name)."""
    return label.replace(" (", "\n(", 1)
