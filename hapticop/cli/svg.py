"""A laid-out drawing as SVG: boxes, circles and bars, edges as polylines with their labels, and
each cluster shown by its colour and a legend rather than a box (see `layered.py` for the layout).
Used by `hapticop graph` when neither graphviz's `dot` nor pygraphviz is installed."""

from __future__ import annotations

from html import escape

from hapticop.cli.drawing import Drawing, Edge
from hapticop.cli.layered import FONT, LINE_H, MARGIN, Box, layout, wrapped

MAX_WIDTH = 2880  # px: a larger drawing is scaled down to this, as graphviz's size attribute does
PALETTE = ("#fff6cc", "#dcecfb", "#e2f5dc", "#fbe3e3", "#ece3fb", "#fbecd9", "#e0f4f4", "#f0f0f0")


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


def _edge_svg(edge: Edge, chain: list[str], boxes: dict[str, Box], vertical: bool) -> list[str]:
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
        out.append(_text(wrapped(edge.label), label_box.x, label_box.y, FONT - 2, edge.color))
    elif edge.label:  # no column between: beside the middle of the line
        (x0, y0), (x1, y1) = points[0], points[-1]
        out.append(_text(edge.label, (x0 + x1) / 2, (y0 + y1) / 2 - 6, FONT - 2, edge.color))
    return out


def _node_svg(label: str, shape: str, box: Box, fill: str, peripheries: int) -> list[str]:
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
