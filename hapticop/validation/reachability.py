"""Exploring what a coordination net can reach, to find unbounded places and dead ends.

A net is open: flag maps feed it from outside. The exploration models that environment
conservatively:

- a place fed by a *tracking source* mirrors a level flag that may be true or false at any
  step, so it is left out of the state and counts as holding one token when a transition
  asks for it (weight 1) and as never enough for heavier arcs;
- a place fed by a *converting source* may receive an event token whenever it is empty;
- a place read by a *converting sink* may lose a token at any step.

From the initial marking every interleaving of transitions and environment moves is
explored breadth first, up to a state limit, with the arcs the coordinator fires
(`coordination.petri.Net`). A marking is *dead* when no sequence of moves
from it ever fires a transition again and none of the net's terminal places is marked;
a place is *unbounded* when a marking strictly covers an earlier one on its own path; the
net *livelocks* when transitions alone can fire in a cycle, so the mediator's "fire to a
steady state" would never end.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import networkx as nx

from hapticop.coordination.petri import Net

DEFAULT_STATE_LIMIT = 20_000


@dataclass(frozen=True)
class Environment:
    """How the flag maps connect a net to the outside, by place name."""

    tracking_sources: frozenset[str] = frozenset()
    converting_sources: frozenset[str] = frozenset()
    converting_sinks: frozenset[str] = frozenset()
    labels: dict[str, str] = field(default_factory=dict, hash=False, compare=False)  # place -> flag(s)


@dataclass
class Finding:
    kind: str  # "unbounded", "dead", "stuck", "livelock"
    marking: dict[str, int]
    trace: list[str]
    place: str = ""


@dataclass
class Analysis:
    states: int
    complete: bool
    findings: list[Finding]


def explore(
    net: Net,
    env: Environment,
    terminal: frozenset[str] = frozenset(),
    state_limit: int = DEFAULT_STATE_LIMIT,
) -> Analysis:
    tracked = {net.index(p) for p in env.tracking_sources}
    kept = [i for i in range(len(net.places)) if i not in tracked]
    position = {place_index: k for k, place_index in enumerate(kept)}
    names = [net.places[i] for i in kept]

    # Transitions over the kept places only; tracked inputs become static guards.
    # An inhibitor arc on a tracked place is a guard the flag being false opens: the environment
    # may leave it open at any step. On a kept place it is a test for zero tokens.
    transitions = []
    for tname, (inputs, outputs, empty) in zip(net.transitions, net.arcs):
        if any(w > 1 for i, w in inputs if i in tracked):
            continue  # a level flag never holds more than one token
        if any(i in tracked and w for i, w in inputs if i in empty):
            continue  # needs the same flag true and false at once
        pre = [(position[i], int(w)) for i, w in inputs if w and i not in tracked]
        post = [(position[i], int(w)) for i, w in outputs if w and i not in tracked]
        zero = [position[i] for i in empty if i not in tracked]
        # A transition guarded by a level flag consumes that token: once per step at most.
        guarded = any(w for i, w in inputs if i in tracked)
        transitions.append((tname, pre, post, zero, guarded))
    events = [position[net.index(p)] for p in sorted(env.converting_sources) if net.index(p) not in tracked]
    emits = [position[net.index(p)] for p in sorted(env.converting_sinks) if net.index(p) not in tracked]
    terminal_positions = [position[net.index(p)] for p in terminal if net.index(p) in position]

    def label(kind: str, k: int) -> str:
        place_name = names[k]
        flag = env.labels.get(place_name)
        return f"{kind} {flag} -> {place_name}" if kind == "event" else f"{place_name} -> {kind} {flag}"

    start = tuple(int(net.initial[i]) for i in kept)
    graph = nx.DiGraph()
    graph.add_node(start)
    parent: dict[tuple, tuple | None] = {start: None}
    findings: list[Finding] = []
    queue = deque([start])
    complete = True

    def trace_to(marking: tuple) -> list[str]:
        steps = []
        node = marking
        while parent[node] is not None:
            steps.append(graph.edges[parent[node], node]["label"])
            node = parent[node]
        return steps[::-1]

    event_set = set(events)

    def covered_ancestor(marking: tuple, via: tuple) -> int | None:
        """A strictly covered ancestor proves a pumpable sequence (Karp and Miller).

        Event places must hold the same count at both ends: an event is offered only
        while its place is empty, so only then does the sequence repeat unchanged.
        """
        node: tuple | None = via
        while node is not None:
            if node != marking and all(
                a == b if k in event_set else a <= b for k, (a, b) in enumerate(zip(node, marking))
            ):
                grown = [k for k, (a, b) in enumerate(zip(node, marking)) if b > a]
                return grown[0]
            node = parent[node]
        return None

    while queue:
        marking = queue.popleft()
        moves: list[tuple[tuple, str, bool]] = []
        for tname, pre, post, zero, guarded in transitions:
            if all(marking[k] >= w for k, w in pre) and not any(marking[k] for k in zero):
                nxt = list(marking)
                for k, w in pre:
                    nxt[k] -= w
                for k, w in post:
                    nxt[k] += w
                moves.append((tuple(nxt), tname, "guarded" if guarded else True))
        for k in events:
            if marking[k] == 0:
                nxt = list(marking)
                nxt[k] = 1
                moves.append((tuple(nxt), label("event", k), False))
        for k in emits:
            if marking[k] > 0:
                nxt = list(marking)
                nxt[k] -= 1
                moves.append((tuple(nxt), label("emit", k), False))
        for nxt, move_label, is_transition in moves:
            new = nxt not in graph
            if not graph.has_edge(marking, nxt):
                graph.add_edge(marking, nxt, label=move_label, transition=is_transition)
            if not new:
                continue
            parent[nxt] = marking
            grown = covered_ancestor(nxt, marking)
            if grown is not None:
                findings.append(Finding("unbounded", {n: v for n, v in zip(names, nxt) if v}, trace_to(nxt),
                                        place=names[grown]))
                return Analysis(graph.number_of_nodes(), False, findings)
            if graph.number_of_nodes() >= state_limit:
                complete = False
                queue.clear()
                break
            queue.append(nxt)

    if not complete:
        return Analysis(graph.number_of_nodes(), False, findings)

    def backwards_from(targets: list[tuple]) -> set[tuple]:
        reached, stack = set(targets), list(targets)
        while stack:
            for before in graph.predecessors(stack.pop()):
                if before not in reached:
                    reached.add(before)
                    stack.append(before)
        return reached

    def is_terminal(node: tuple) -> bool:
        return any(node[k] > 0 for k in terminal_positions)

    # `graph` was built breadth first, so iteration order is by distance from the start.
    can_fire_again = backwards_from([n for n in graph
                                     if any(d["transition"] for *_, d in graph.out_edges(n, data=True))])
    dead = [n for n in graph if n not in can_fire_again and not is_terminal(n)]
    for node in dead[:3]:
        findings.append(Finding("dead", {n: v for n, v in zip(names, node) if v}, trace_to(node)))
    if terminal_positions and not dead:
        can_finish = backwards_from([n for n in graph if is_terminal(n)])
        stuck = [n for n in graph if n not in can_finish]
        if stuck:
            node = stuck[0]
            findings.append(Finding("stuck", {n: v for n, v in zip(names, node) if v}, trace_to(node)))

    transition_only = nx.DiGraph(
        (u, v, d) for u, v, d in graph.edges(data=True) if d["transition"] is True
    )
    try:
        cycle = nx.find_cycle(transition_only)
    except nx.NetworkXNoCycle:
        cycle = None
    if cycle:
        first = cycle[0][0]
        findings.append(
            Finding("livelock", {n: v for n, v in zip(names, first) if v},
                    [transition_only.edges[u, v]["label"] for u, v, *_ in cycle])
        )
    return Analysis(graph.number_of_nodes(), True, findings)
