"""Building one process's share of a system: its activities, ports and thread loops.

The main process builds the threads deployed in it; a process-deployed thread builds
only itself, from the same composition and the same shared region, so both sides wire
exactly the same stream buffers.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from hapticop.composition.description import Composition
from hapticop.composition.loader import Loaded, ResolvedActivity
from hapticop.runtime import cycle_log
from hapticop.runtime.context import ActivityContext, CycleClock, FlagView, InputPort, OutputPort, SimulationTimer
from hapticop.runtime.cycle_log import CycleLog
from hapticop.runtime.latencies import OriginRelay
from hapticop.runtime.logs import Level, Logger, LogWriter
from hapticop.runtime.region import Layout, Region
from hapticop.runtime.streams import QUEUE_HEADER, RecorderRing, latest_nbytes
from hapticop.runtime.thread import ActivityRunner, CyclicThread
from hapticop.runtime.transport import connect_reader, transport_of


def layout_of(loaded: Loaded, flags: list[str], rings: dict[str, int] | None = None) -> Layout:
    """The region's layout; `flags` as validation's graph lists them (`Validated.flags`), `rings` the
    recorder rings the run's observer reserves (capacity per stream)."""
    return Layout.build(loaded.composition, loaded.activities, flags, rings)


def thread_of(composition: Composition) -> dict[str, str]:
    """Which thread each scheduled activity belongs to."""
    owner = {}
    for thread_name, spec in composition.threads.items():
        for members in spec.schedules.values():
            for member in members:
                owner.setdefault(member, thread_name)
    return owner


def activity_rng(seed: int, name: str) -> np.random.Generator:
    """Independent, reproducible randomness per activity: the same seed, the same run."""
    return np.random.default_rng([seed, zlib.crc32(name.encode())])


@dataclass
class Built:
    threads: dict[str, CyclicThread]
    runners: dict[str, ActivityRunner]


def build(loaded: Loaded, region: Region, thread_names: list[str], clock, writer: LogWriter, seed: int,
          apply_realtime: bool, coordination: Any = None) -> Built:
    """`coordination`: the mediator's handle, in the main process only."""
    composition = loaded.composition
    owner = thread_of(composition)
    transports = _transports(loaded, region, owner, clock.virtual)
    runners: dict[str, ActivityRunner] = {}
    threads: dict[str, CyclicThread] = {}
    for thread_name in thread_names:
        spec = composition.threads[thread_name]
        members = [a for a, t in owner.items() if t == thread_name]
        members.sort(key=list(composition.activities).index)
        mine = {}
        for name in members:
            resolved = loaded.activities[name]
            mine[name] = runners[name] = make_runner(name, resolved, composition, region, transports, clock, writer,
                                                      seed, coordination)
        log = writer.logger(f"thread-{thread_name}", Level[spec.log.upper()], clock.now_ns)
        threads[thread_name] = CyclicThread(thread_name, spec, region, mine, clock, log, apply_realtime)
    return Built(threads, runners)


def _transports(loaded: Loaded, region: Region, owner: dict[str, str], one_thread: bool) -> dict[str, list]:
    """Transport objects over the region's buffers, one set per stream."""
    return {name: make_transports(loaded, region, name, owner, one_thread=one_thread)
            for name in loaded.composition.streams}


def make_transports(loaded: Loaded, region: Region, stream: str, owner: dict[str, str],
                    one_thread: bool = False) -> list:
    """The transports of one stream over the buffers the layout placed for it (at start-up, or in
    the arena when added live): a latest slot, or one queue ring per reader; then, if the run
    reserved one, the recorder's ring (which only the writer sees: readers take theirs by index).

    `one_thread`: every loop of the system runs in this thread, one after the other (the virtual
    clock), so no reader needs the seqlock's retries.
    """
    transport = transport_of(loaded, stream)
    spec = transport.spec
    reader_threads = {owner.get(r.split(".")[0]) for r in spec.readers}
    same_thread = reader_threads == {owner.get(spec.writer.split(".")[0])}
    views = [region.buffer_at(t.offset, t.nbytes) for t in region.layout.transports[stream]]
    objects = transport.objects(views, synchronised=not same_thread and not one_thread)
    ring = region.layout.recorded.get(stream)
    if ring is not None:
        objects.append(transport.ring(region.buffer_at(ring.offset, ring.nbytes)))
    return objects


def make_context(name: str, interface, params, region: Region, clock, log: Logger, rng: np.random.Generator,
                 run_dir, period_ns: int, coordination: Any = None,
                 track: bool = False) -> tuple[ActivityContext, CycleClock]:
    """What an activity's block sees, over its region: the one place an activity's context is built
    (a run's activities, a live addition, a block harness alike). Its ports are not connected yet;
    the returned cycle clock is the one its runner sets at each step."""
    cycle = CycleClock()
    inputs = {p: InputPort(p, spec, cycle.now_ns, track) for p, spec in interface.inputs.items()}
    outputs = {p: OutputPort(p, spec, clock.now_ns, track) for p, spec in interface.outputs.items()}
    for port in inputs.values():
        port.log = log  # a stream whose every sample arrives stale says so in its reader's log
    layout = region.layout
    flags = FlagView(region.flags, layout.flag_index, name,
                     list(interface.flags_written) + list(interface.flags_read))
    index = layout.activity_index[name]
    context = ActivityContext(name, params, SimpleNamespace(**inputs), SimpleNamespace(**outputs), flags, clock, log,
                              rng, Path(run_dir), SimulationTimer(region.sim_ns, index), coordination, period_ns,
                              region.waiting[index])
    return context, cycle


def make_runner(name: str, resolved: ResolvedActivity, composition: Composition, region: Region,
                transports: dict[str, list], clock, writer: LogWriter, seed: int,
                coordination: Any = None) -> ActivityRunner:
    """The block instance of one activity, its ports wired to the given transports."""
    iface = resolved.interface
    track = bool(composition.latencies)
    log = writer.logger(name, Level[resolved.spec.log.upper()], clock.now_ns)
    thread = thread_of(composition).get(name)
    period_ns = composition.threads[thread].period if thread else 0
    context, cycle = make_context(name, iface, resolved.params, region, clock, log, activity_rng(seed, name),
                                  writer.run_dir, period_ns, coordination, track)
    inputs, outputs = vars(context.inputs), vars(context.outputs)
    sinks = []
    for slot, latency in enumerate(composition.latencies.values()):
        activity, port = latency.source.split(".")
        if activity == name:
            outputs[port].origin_slots += (slot,)
        activity, port = latency.sink.split(".")
        if activity == name:
            sinks.append((inputs[port], slot))
    relay = (OriginRelay(list(inputs.values()), list(outputs.values()), sinks, region, clock.now_ns)
             if track else None)
    for stream_name, spec in composition.streams.items():
        objects = transports.get(stream_name)
        if objects is None:
            continue
        if spec.writer.split(".")[0] == name:
            outputs[spec.writer.split(".")[1]].transports.extend(objects)
        for index, reader in enumerate(spec.readers):
            activity, port = reader.split(".")
            if activity == name:
                connect_reader(spec, inputs[port], objects, index)
    block = resolved.block(context)
    runner = ActivityRunner(name, block, region, resolved.spec.start == "on_request", log, relay, cycle)
    cycles = region.layout.cycles.get(name)
    if cycles is not None:
        flushes = runner.flushes
        port = cycle_log.port_of(iface, flushes)
        capacity = (cycles.nbytes - QUEUE_HEADER.itemsize) // latest_nbytes(port)
        ring = RecorderRing(region.buffer_at(cycles.offset, cycles.nbytes), port, capacity, cycles.stream)
        runner.cycle_log = CycleLog(name, iface, flushes, ring, region.flags, region.state,
                                    region.layout.owner_index[name], region.layout.flag_index,
                                    list(inputs.values()), cycle, runner.parameters)
    return runner
