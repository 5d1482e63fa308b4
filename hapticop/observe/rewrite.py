"""Replay as a rewrite of the composition: the recorded activity on the ordinary runtime, fed by the recording.

From a recording, `rewrite` writes a composition of its own: the activity replayed, as it ran
(its block, its recorded parameters), on a thread of its own behind a `recorded_source` that
publishes on each of its inputs the recorded stream, sample by sample, in the cycle that saw
it (`observe.recorded_source`); a mediator, and beside it any activity the replayed one needs
(configured, never started, so what it tells its run is there); its outputs recorded. That file
runs through `System` under the virtual clock as `hapticop compose` runs one: contexts, life
cycle, parameter hand-over and streams are the run's own.

Only the times are the recording's: `RecordedCycles` paces the replayed thread at the recorded
cycles' times (`runtime.pacing`), so a wall-clock run's missed and late cycles are replayed as they
happened, and before each puts back the requests and flags the cycle started from and the
parameters the run had handed over by then; it notes where the replayed life cycle leaves the
recorded one. After the last recorded cycle the thread cleans and the run ends.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

import numpy as np
from pydantic import ValidationError

from hapticop.composition.lcsm import State
from hapticop.observe.replay_run import (
    ReplayError,
    Run,
    inputs_of,
    outputs_of,
    parameter_events_topic,
    parameters_of,
    resolve_block,
    same_kind,
)
from hapticop.recording.reading import Series
from hapticop.runtime import cycle_log
from hapticop.runtime.assembly import thread_of

MAIN, PACED = "main", "replayed"  # the rewrite's threads: the mediator's, and the replayed activity's
WARM_UP = 20  # periods before the first recorded cycle: the replayed thread's own life cycle, and the mediator's
BESIDE_CYCLES = 1000  # periods an activity needed beside the replayed one may take to configure


def _unique(wanted: str, taken: set[str]) -> str:
    name, n = wanted, 1
    while name in taken:
        n += 1
        name = f"{wanted}_{n}"
    taken.add(name)
    return name


@dataclass
class Rewrite:
    """The rewritten composition (a YAML tree) and what the replay needs to know of it."""

    tree: dict
    activity: str
    source: str
    start_ns: int  # the virtual clock's first time
    inputs: list[str]  # the recorded streams the source publishes
    outputs: list[tuple[str, str]]  # (stream, port): the replayed activity's recorded outputs
    beside: list[str] = field(default_factory=list)


def rewrite(run: Run, activity: str) -> Rewrite:
    """The composition that replays `activity` from the recording (checked first: a `ReplayError`
    says what does not fit)."""
    composition = run.loaded.composition
    resolved = run.loaded.activities[activity]
    block_type = resolve_block(run, activity)
    params = parameters_of(run, activity, block_type)
    interface = block_type.declare(params)
    run.load([cycle_log.stream_of(activity)] + [stream for stream, _ in inputs_of(run, activity)]
             + [stream for stream, _ in outputs_of(run, activity)])  # one pass over the file
    rows = run.series(cycle_log.stream_of(activity))
    expected = cycle_log.columns(interface, block_type.implements_flush())
    if json.loads(rows.info.doc or "[]") != expected:
        raise ReplayError(f"{run.path}: activity '{activity}': its recorded cycles do not have the columns its "
                          f"block declares with the recorded parameters ({', '.join(expected)})")
    if not len(rows.publish_ns):
        raise ReplayError(f"{run.path}: activity '{activity}' recorded no cycle: there is nothing to replay")
    period = composition.threads[thread_of(composition)[activity]].period
    needs = [need.activity for need in block_type.needs_of(params) if need.activity in run.loaded.activities]
    beside = {name: parameters_of(run, name, resolve_block(run, name)) for name in needs}
    taken = {activity, *beside}
    source, mediator = _unique("recorded", taken), _unique("mediator", taken)

    streams: dict[str, dict] = {}
    published: dict[str, dict] = {}
    for stream, port in inputs_of(run, activity):
        spec, port_spec, samples = composition.streams[stream], interface.inputs[port], run.series(stream)
        same_kind(run, stream, f"input '{port}'", port_spec, samples.info)
        published[port] = {"stream": stream, "paced_by": port, **_typed(port_spec)}
        streams[stream] = {"from": f"{source}.{port}", "to": [f"{activity}.{port}"],
                           "policy": spec.policy.model_dump(mode="json")}
        if spec.max_age:
            streams[stream]["max_age"] = f"{spec.max_age}ns"
    outputs = outputs_of(run, activity)
    taken_back: dict[str, dict] = {}
    for stream, port in outputs:
        port_spec = interface.outputs[port]
        same_kind(run, stream, f"output '{port}'", port_spec, run.series(stream).info)
        back = _unique(f"replayed_{port}", set(taken_back) | set(published))
        taken_back[back] = {"stream": stream, **_typed(port_spec)}
        streams[stream] = {"from": f"{activity}.{port}", "to": [f"{source}.{back}"]}
    for name in beside:  # its inputs connected, so that it validates; it never runs to read them
        for stream, port in inputs_of(run, name):
            if stream in streams:
                streams[stream]["to"].append(f"{name}.{port}")
                continue
            silent = _unique(f"{name}_{port}", set(published) | set(interface.inputs))
            published[silent] = {"stream": stream, **_typed(run.loaded.activities[name].interface.inputs[port])}
            streams[stream] = {"from": f"{source}.{silent}", "to": [f"{name}.{port}"]}

    def entry(name: str, parameters, start: str) -> dict:
        spec = run.loaded.activities[name].spec
        return {"block": spec.block, "params": parameters.model_dump(mode="json"), "start": start, "log": "error"}

    first = int(rows.publish_ns[0])
    start = max(0, first - (BESIDE_CYCLES if beside else WARM_UP) * period)  # a recording's times are not negative
    span = int(rows.publish_ns[-1]) - start
    tree = {
        "version": 1,
        "name": f"replay_{activity}",
        "threads": {MAIN: {"period": f"{period}ns", "deploy": "main", "schedules": {0: [mediator, *beside]}},
                    PACED: {"period": f"{period}ns", "schedules": {0: [source, activity]}}},
        "activities": {
            mediator: {"block": "mediator"},
            **{name: entry(name, p, "on_request") for name, p in beside.items()},
            source: {"block": "recorded_source", "params": {
                "recording": str(run.path), "cycles": cycle_log.stream_of(activity), "outputs": published,
                "compared": taken_back}},
            activity: entry(activity, params, resolved.spec.start),
        },
        "streams": streams,
        "record": {"streams": [stream for stream, _ in outputs]},
        "duration": f"{span + 10**9}ns",  # a bound only: the pacing ends the run after the last recorded cycle
    }
    return Rewrite(tree, activity, source, start, [s for s, _ in inputs_of(run, activity)], outputs, list(beside))


def _typed(port) -> dict:
    return {"dtype": np.dtype(port.dtype).name, "shape": list(port.shape), "unit": port.unit}


class RecordedCycles:
    """The replayed thread paced at the recorded cycles' times, each cycle started from what the
    recorded one started from (`runtime.pacing.Pacing`)."""

    def __init__(self, run: Run, rewritten: Rewrite, origin_ns: int):
        activity = rewritten.activity
        self.run, self.activity, self.origin_ns = run, activity, origin_ns
        self.rows: Series = run.series(cycle_log.stream_of(activity))
        self.times = self.rows.publish_ns
        # Before the first recorded cycle every thread cycles this often: the mediator starts the replayed
        # thread, which configures itself, and whoever is beside configures, all in the time there is.
        setup = (BESIDE_CYCLES if rewritten.beside else WARM_UP) * 2
        self.setup_ns = max(1, (int(self.times[0]) - rewritten.start_ns) // setup)
        self.block_type = resolve_block(run, activity)
        self.columns = json.loads(self.rows.info.doc)
        self.next = 0  # the first recorded cycle not yet started
        self.handed = 0  # parameter events handed over so far
        self.diverged = ""
        self.computed = 0  # recorded cycles that ran the block's compute
        self.stepped = False  # the last cycle was a recorded one, not yet counted
        self.ended = False
        self.system = None

    def attach(self, system) -> None:
        """The system built from the rewrite, just before it runs (`run_system`'s `on_start`)."""
        self.system = system
        index, name = system.flag_index, self.activity
        self.flag_indices = [index[f"{name}.lcsm.{c[8:]}" if c.startswith("request.") else f"{name}.{c[5:]}"]
                             for c in self.columns if c.startswith(("request.", "flag."))]

    def next_ns(self, thread: str, deadline_ns: int, period_ns: int, running: bool) -> int:
        first = int(self.times[0])
        if thread == PACED and running:
            at = int(np.searchsorted(self.times, deadline_ns, side="right"))
            return int(self.times[at]) if at < len(self.times) else deadline_ns + period_ns
        if deadline_ns < first:
            return min(deadline_ns + self.setup_ns, first if thread == PACED else deadline_ns + period_ns)
        return deadline_ns + period_ns

    def before(self, thread: str, now_ns: int) -> None:
        if thread != PACED or self.system is None:
            return
        runner = self.system.runners[self.activity]
        if self.stepped and runner.computing:
            self.computed += 1
        self.stepped = False
        times, i = self.times, self.next
        while i < len(times) and times[i] < now_ns:
            i += 1
        self.next = i
        if i < len(times) and times[i] == now_ns:
            self._start(self.rows.values[i], now_ns, runner)
            self.next, self.stepped = i + 1, True
        elif i == len(times) and not self.ended:  # past the last recorded cycle: the thread cleans, the run ends
            self.ended = True
            self.system.threads[PACED].lifecycle.request_cleaning()
            self.system.request_shutdown()

    def _start(self, row: np.ndarray, now_ns: int, runner) -> None:
        state = self.system.region.state_of(self.activity)
        if int(state) != int(row[0]) and not self.diverged:
            self.diverged = (f"at {self.at(now_ns):.6f} s the run's life cycle was {State(int(row[0])).flag_name}, "
                             f"the replay's {state.flag_name}")
        if int(row[1]) != self.handed:
            self._hand(int(row[1]), now_ns, runner)
        flags = self.system.region.flags
        for k, index in enumerate(self.flag_indices):
            flags[index] = row[2 + k]

    def _hand(self, revision: int, now_ns: int, runner) -> None:
        """The parameters the run's block held from this cycle on handed to its runner, as the run handed
        them (events the run handed between two steps arrive as one, the names changed by any)."""
        events = {e.revision: e for e in self.run.parameter_events() if e.activity == self.activity}
        wanted = range(self.handed + 1, revision + 1)
        missing = [n for n in wanted if n not in events]
        if missing or revision < self.handed:
            raise ReplayError(f"{self.run.path}: activity '{self.activity}' held parameter set {revision} from "
                              f"{self.at(now_ns):.6f} s, but the recording's {parameter_events_topic} has no event "
                              f"{missing[0] if missing else revision} for it")
        try:
            params = self.block_type.Params.model_validate(events[revision].parameters)
        except ValidationError as error:
            raise ReplayError(f"{self.run.path}: {parameter_events_topic}, activity '{self.activity}', revision "
                              f"{revision}: {error.errors()[0]['msg']}") from None
        runner.retune(params, frozenset(name for n in wanted for name in events[n].changed))
        self.handed = revision

    def at(self, t_ns: int) -> float:
        return (t_ns - self.origin_ns) / 1e9
