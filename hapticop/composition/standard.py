"""The standard coordination, declared once under `coordination.standard`, written out as nets and flag maps.

Most applications coordinate the same way (thesis §6.2): start the threads that wait for a
request, select their schedules, wait until the devices run, and on Ctrl+C clean in stages
(the haptic loop, then the devices, then the threads). Written by hand that is a transition
list and a flag-map entry per thread and per activity; declared here it is a few lists, and
the expansion writes the three nets of docs/coordination.md §8 (`mediator`, `thread_lcsm`,
`thread_scheduler`) before anything is validated, so every check and the runtime see
ordinary nets. Each expanded entry remembers the part of the declaration that asked for it,
so a finding about it points there.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

from ruamel.yaml.comments import CommentedMap, CommentedSeq

from hapticop.composition.description import Composition, Coordination, FlagMap, PetriNet, StandardCoordination
from hapticop.composition.diagnostics import Diagnostic, Path

STANDARD: Path = ("coordination", "standard")
MEDIATOR, THREAD_LCSM, THREAD_SCHEDULER = "mediator", "thread_lcsm", "thread_scheduler"
SHUTDOWN_FLAG = "system.shutdown_requested"
KINDS = ("converting_sources", "tracking_sources", "converting_sinks", "tracking_sinks")
COUPLING_FLAGS = {
    "start_threads": "the mediator net asks the thread LCSM net to run the threads",
    "threads_running": "every thread started on request is running",
    "select_schedules": "the mediator net asks the scheduler net to select the schedules",
    "stop_threads": "the mediator net asks the thread LCSM net to clean the threads",
    "threads_done": "every thread started on request is done",
}


@dataclass
class Expansion:
    """The nets, flag maps and coupling flags a declaration stands for, as a file would write them."""

    flags: dict[str, str] = field(default_factory=dict)
    nets: dict[str, dict] = field(default_factory=dict)
    flag_maps: dict[str, dict] = field(default_factory=dict)
    origins: dict[Path, Path] = field(default_factory=dict)  # an expanded entry's path -> what asked for it
    diagnostics: list[Diagnostic] = field(default_factory=list)

    def origin_of(self, path: Path) -> Path | None:
        """The part of the declaration behind the expanded entry at `path` (its longest known prefix)."""
        for end in range(len(path), 2, -1):
            origin = self.origins.get(tuple(path[:end]))
            if origin is not None:
                return origin
        return None

    def merged_into(self, coordination: Coordination) -> Coordination:
        """`coordination` with the expansion ahead of its hand-written entries (nets fire in that order)."""
        return Coordination(
            standard=coordination.standard,
            flags={**self.flags, **coordination.flags},
            nets={**{n: PetriNet.model_validate(s) for n, s in self.nets.items()}, **coordination.nets},
            flag_maps={**{n: FlagMap.model_validate(s) for n, s in self.flag_maps.items()},
                       **coordination.flag_maps},
        )


class _Writer:
    """Builds the YAML-shaped nets and flag maps, noting who asked for each entry and refusing a name twice."""

    def __init__(self) -> None:
        self.out = Expansion()

    def net(self, name: str, doc: str, marked: str, terminal: str) -> None:
        self.out.nets[name] = {"doc": doc, "places": {}, "transitions": {}, "marking": {marked: 1},
                               "terminal": [terminal]}
        self.out.flag_maps[name] = {"net": name, **{kind: {} for kind in KINDS}}
        self.out.origins[("coordination", "nets", name)] = STANDARD
        self.out.origins[("coordination", "flag_maps", name)] = STANDARD
        for place in (marked, terminal):
            self.place(name, place, STANDARD)

    def place(self, net: str, name: str, origin: Path) -> None:
        self._once(("coordination", "nets", net, "places", name), origin, f"place '{name}' of net '{net}'")
        self.out.nets[net]["places"][name] = None

    def transition(self, net: str, name: str, inputs: list[str], outputs: list[str], origin: Path) -> None:
        self._once(("coordination", "nets", net, "transitions", name), origin, f"transition '{name}' of net '{net}'")
        self.out.nets[net]["transitions"][name] = {"in": inputs, "out": outputs}

    def bind(self, net: str, kind: str, flag: str, place: str, origin: Path) -> None:
        self._once(("coordination", "flag_maps", net, kind, flag), origin, f"{kind[:-1].replace('_', ' ')} '{flag}'")
        self.out.flag_maps[net][kind][flag] = place

    def _once(self, path: Path, origin: Path, what: str) -> None:
        """Two parts of the declaration writing one name: the first such clash is reported (the rest follow)."""
        first = self.out.origins.setdefault(path, origin)
        if first != origin and not self.out.diagnostics:
            self.out.diagnostics.append(Diagnostic(
                "standard-clash", f"{what} would be written twice: for '{_dotted(first)}' and for "
                f"'{_dotted(origin)}'", max(first, origin, key=len),
                hint="the standard nets name places after threads, activities, stages and end events; rename one "
                "(docs/coordination.md section 8 lists the names)"))


def _dotted(path: Path) -> str:
    return ".".join(str(part) for part in path)


def expand(composition: Composition) -> Expansion:
    """The nets and flag maps `composition.coordination.standard` stands for (an empty expansion without one)."""
    spec = composition.coordination.standard
    if spec is None:
        return Expansion()
    w = _Writer()
    threads = list(spec.threads) if spec.threads is not None else [
        name for name, thread in composition.threads.items() if thread.start == "on_request"]
    thread_origin = {t: STANDARD + ("threads", i) if spec.threads is not None else STANDARD
                     for i, t in enumerate(threads)}
    select = {name: 1 for name, thread in composition.threads.items() if 1 in thread.schedules}
    select.update(spec.select)
    selected = {t: sid for t, sid in select.items() if sid != 0}
    if threads:
        w.out.flags.update((n, COUPLING_FLAGS[n]) for n in ("start_threads", "threads_running", "stop_threads",
                                                             "threads_done"))
    if selected:
        w.out.flags["select_schedules"] = COUPLING_FLAGS["select_schedules"]
    for name in w.out.flags:
        w.out.origins[("coordination", "flags", name)] = STANDARD

    _mediator(w, spec, threads, bool(selected))
    if threads:
        _thread_lcsm(w, threads, thread_origin)
    if selected:
        _thread_scheduler(w, selected, {t: STANDARD + ("select", t) if t in spec.select else STANDARD
                                        for t in selected})
    return w.out


def _mediator(w: _Writer, spec: StandardCoordination, threads: list[str], selects: bool) -> None:
    """Start, select, wait, operate; on an end, clean stage by stage, then the threads, then exit."""
    net, S = MEDIATOR, STANDARD
    w.net(net, "the standard start and ordered shutdown (coordination.standard)", "START", "EXIT")
    for place in ("WAITING_DEVICES", "OPERATING", "SHUTDOWN"):
        w.place(net, place, S)
    w.bind(net, "converting_sources", SHUTDOWN_FLAG, "SHUTDOWN", S)
    begin = ["WAITING_DEVICES"] + (["REQ_SELECT_SCHEDULES"] if selects else [])
    if selects:
        w.place(net, "REQ_SELECT_SCHEDULES", S)
        w.bind(net, "converting_sinks", "flags.select_schedules", "REQ_SELECT_SCHEDULES", S)
    if threads:
        for place in ("THREADS_REQUESTED", "REQ_START_THREADS", "THREADS_RUNNING", "STOPPING_THREADS",
                      "REQ_STOP_THREADS", "THREADS_DONE"):
            w.place(net, place, S)
        w.transition(net, "start_threads", ["START"], ["THREADS_REQUESTED", "REQ_START_THREADS"], S)
        w.transition(net, "threads_running", ["THREADS_REQUESTED", "THREADS_RUNNING"], begin, S)
        w.bind(net, "converting_sinks", "flags.start_threads", "REQ_START_THREADS", S)
        w.bind(net, "tracking_sources", "flags.threads_running", "THREADS_RUNNING", S)
        w.bind(net, "converting_sinks", "flags.stop_threads", "REQ_STOP_THREADS", S)
        w.bind(net, "tracking_sources", "flags.threads_done", "THREADS_DONE", S)
        stop_threads = ["STOPPING_THREADS", "REQ_STOP_THREADS"]
    else:
        w.transition(net, "select_schedules" if selects else "begin", ["START"], begin, S)
        stop_threads = ["EXIT"]

    running = []
    for i, activity in enumerate(spec.wait_for):
        place = f"{activity.upper()}_RUNNING"
        w.place(net, place, S + ("wait_for", i))
        w.bind(net, "tracking_sources", f"{activity}.lcsm.running", place, S + ("wait_for", i))
        running.append(place)
    w.transition(net, "devices_running", ["WAITING_DEVICES", *running], ["OPERATING"], S + ("wait_for",))

    stages = list(spec.clean.items())
    first_stop = _stage_start(w, *stages[0]) if stages else stop_threads
    w.transition(net, "abort_start", ["START", "SHUTDOWN"], stop_threads, S)
    if threads:
        w.transition(net, "abort_threads", ["THREADS_REQUESTED", "SHUTDOWN"], stop_threads, S)
    w.transition(net, "abort_devices", ["WAITING_DEVICES", "SHUTDOWN"], first_stop, S)
    w.transition(net, "shutdown", ["OPERATING", "SHUTDOWN"], first_stop, S)
    for flag, place in spec.ends.items():
        origin = S + ("ends", flag)
        w.place(net, place, origin)
        w.bind(net, "converting_sources", flag, place, origin)
        w.transition(net, place.lower(), ["OPERATING", place], first_stop, origin)
    for k, (stage, activities) in enumerate(stages):
        origin = S + ("clean", stage)
        done = []
        for i, activity in enumerate(activities):
            place = f"{activity.upper()}_DONE"
            w.place(net, place, origin + (i,))
            w.bind(net, "tracking_sources", f"{activity}.lcsm.done", place, origin + (i,))
            done.append(place)
        after = _stage_start(w, *stages[k + 1]) if k + 1 < len(stages) else stop_threads
        w.transition(net, f"{stage}_done", [f"STOPPING_{stage.upper()}", *done], after, origin)
    if threads:
        w.transition(net, "threads_done", ["STOPPING_THREADS", "THREADS_DONE"], ["EXIT"], S)
    w.bind(net, "tracking_sinks", "system.exit", "EXIT", S)

    for flag, place in spec.sources.items():  # a place of its own: the standard places' tokens are the net's
        w.place(net, place, S + ("sources", flag))
        w.bind(net, "tracking_sources", flag, place, S + ("sources", flag))
    for flag, place in spec.sinks.items():
        w.bind(net, "tracking_sinks", flag, place, S + ("sinks", flag))


def _stage_start(w: _Writer, stage: str, activities: list[str]) -> list[str]:
    """The places that begin cleaning stage `stage`: its marker and one request per activity."""
    origin = STANDARD + ("clean", stage)
    places = [f"STOPPING_{stage.upper()}"]
    w.place(MEDIATOR, places[0], origin)
    for i, activity in enumerate(activities):
        place = f"REQ_CLEAN_{activity.upper()}"
        w.place(MEDIATOR, place, origin + (i,))
        w.bind(MEDIATOR, "converting_sinks", f"{activity}.lcsm.request_cleaning", place, origin + (i,))
    return places + [f"REQ_CLEAN_{activity.upper()}" for activity in activities]


def _thread_lcsm(w: _Writer, threads: list[str], origin: dict[str, Path]) -> None:
    """Couples the threads' LCSMs: run them all on request, clean them all on request (the thesis's flag map 1)."""
    net, S = THREAD_LCSM, STANDARD
    w.net(net, "runs and cleans the threads started on request (coordination.standard)", "IDLE", "DONE")
    for place in ("START_REQUESTED", "STARTING", "RUNNING", "STOP_REQUESTED", "STOPPING"):
        w.place(net, place, S)
    names = {t: t.upper() for t in threads}
    for pattern, flag in (("REQ_RUN_{}", "request_running"), ("{}_RUNNING", "running"),
                          ("REQ_CLEAN_{}", "request_cleaning"), ("{}_DONE", "done")):
        kind = "converting_sinks" if flag.startswith("request") else "tracking_sources"
        for t in threads:
            w.place(net, pattern.format(names[t]), origin[t])
            w.bind(net, kind, f"threads.{t}.lcsm.{flag}", pattern.format(names[t]), origin[t])
    run = [f"REQ_RUN_{names[t]}" for t in threads]
    clean = [f"REQ_CLEAN_{names[t]}" for t in threads]
    w.transition(net, "request_running", ["IDLE", "START_REQUESTED"], ["STARTING", *run], S)
    w.transition(net, "all_running", ["STARTING", *(f"{names[t]}_RUNNING" for t in threads)], ["RUNNING"], S)
    for state in ("idle", "starting", "running"):
        w.transition(net, f"stop_{state}", [state.upper(), "STOP_REQUESTED"], ["STOPPING", *clean], S)
    w.transition(net, "all_done", ["STOPPING", *(f"{names[t]}_DONE" for t in threads)], ["DONE"], S)
    w.bind(net, "converting_sources", "flags.start_threads", "START_REQUESTED", S)
    w.bind(net, "converting_sources", "flags.stop_threads", "STOP_REQUESTED", S)
    w.bind(net, "tracking_sinks", "flags.threads_running", "RUNNING", S)
    w.bind(net, "tracking_sinks", "flags.threads_done", "DONE", S)


def _thread_scheduler(w: _Writer, selected: dict[str, int], origin: dict[str, Path]) -> None:
    """Selects every thread's schedule at once on request (the thesis's flag map 2)."""
    net, S = THREAD_SCHEDULER, STANDARD
    w.net(net, "selects the threads' schedules (coordination.standard)", "IDLE", "SELECTED")
    w.place(net, "SELECT_REQUESTED", S)
    requests = []
    for t, sid in selected.items():
        place = f"SELECT_SCHEDULE_{sid}_{t.upper()}"
        w.place(net, place, origin[t])
        w.bind(net, "converting_sinks", f"threads.{t}.select_schedule.{sid}", place, origin[t])
        requests.append(place)
    ids = set(selected.values())
    name = f"select_schedule_{ids.pop()}" if len(ids) == 1 else "select_schedules"
    w.transition(net, name, ["IDLE", "SELECT_REQUESTED"], ["SELECTED", *requests], S)
    w.bind(net, "converting_sources", "flags.select_schedules", "SELECT_REQUESTED", S)


def clashes(expansion: Expansion, coordination: Coordination) -> list[Diagnostic]:
    """Hand-written entries that take a name the expansion writes: each is refused where it is written."""
    found = []
    for collection in ("flags", "nets", "flag_maps"):
        for name in getattr(expansion, collection).keys() & getattr(coordination, collection).keys():
            found.append(Diagnostic(
                "standard-clash", f"'{name}' is written by hand and by coordination.standard",
                ("coordination", collection, name),
                hint=f"coordination.standard writes the nets {MEDIATOR}, {THREAD_LCSM} and {THREAD_SCHEDULER}, their "
                "flag maps and the coupling flags they share; rename the hand-written one"))
    return found


def expanded_tree(tree: Any, expansion: Expansion) -> CommentedMap:
    """The document with `coordination.standard` replaced by what it stands for (for `hapticop expand`)."""
    tree = copy.deepcopy(tree)
    coordination = tree.setdefault("coordination", CommentedMap())
    coordination.pop("standard", None)
    for collection in ("flags", "nets", "flag_maps"):
        written = CommentedMap((name, _inline(entry)) for name, entry in getattr(expansion, collection).items())
        written.update(coordination.get(collection) or {})
        if written:
            coordination[collection] = written
    return tree


def _inline(node: Any) -> Any:
    """Arc lists and markings written inline, as people write them; empty flag-map kinds left out."""
    if isinstance(node, list):
        seq = CommentedSeq(node)
        seq.fa.set_flow_style()
        return seq
    if not isinstance(node, dict):
        return node
    mapping = CommentedMap((k, _inline(v)) for k, v in node.items() if v != {} or k in ("places", "transitions"))
    if "marking" in mapping:
        mapping["marking"].fa.set_flow_style()
    return mapping
