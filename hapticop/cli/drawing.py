"""What one view of `hapticop graph` shows, before any layout: nodes in labelled clusters, and edges."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Node:
    label: str  # lines joined by "\n"
    shape: str = "box"  # box, circle, bar, note, point
    cluster: str | None = None
    fill: str = "white"
    peripheries: int = 1


@dataclass
class Edge:
    tail: str
    head: str
    label: str = ""
    style: str = "solid"  # solid, dashed, dotted
    color: str = "black"
    tooltip: str = ""
    arrowhead: str = "normal"  # normal, none, odot (an inhibitor arc)


@dataclass
class Drawing:
    """What one view shows, before any layout: nodes (grouped into labelled clusters) and edges."""

    title: str
    nodes: dict[str, Node] = field(default_factory=dict)
    edges: list[Edge] = field(default_factory=list)
    clusters: dict[str, str] = field(default_factory=dict)  # id -> label
    parents: dict[str, str] = field(default_factory=dict)  # a cluster drawn inside another (a host's threads)
    aligned: bool = False  # one ranking across clusters (tidy for threads; too wide for nets)
