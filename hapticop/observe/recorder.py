"""The recorder: every recorded stream's own ring, drained off the real-time path into one MCAP file and the live view.

Each recorded stream's writer pushes every sample into a ring of its own in the shared region
(`region.Layout.recorded`), beside its other transports: the loop copies the sample and moves
on, never waiting and never allocating. The recorder drains the rings in batches, writes each
sample with its number and publication stamp (`RecordingFile`), and hands the same batches to
its views, which may derive channels of their own from them (a scan from two streams, the
robot's frames from a pose) without the loops knowing. A ring the recorder falls a whole
ring behind on is overwritten, and the lost samples are counted, never waited for. Beside the
rings it follows sources of its own: each loop's timing counters (`timing_channels`) and the
run's log files (`log_channel`); a network bridge's link figures are ordinary streams. Whatever it
writes goes to its outputs (`recording.outputs`):
the file, the live view (`recording.live`, `compose --view`), or both.

On the wall clock the recorder is a process of its own at normal scheduling, which leaves
with its parent; under the virtual clock the main process drains the rings itself between
two main-thread cycles, so a test's recording is the same every run (`recorder_process`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from hapticop.blocks.interface import Port
from hapticop.composition.loader import Loaded
from hapticop.observe import cycle_rings
from hapticop.observe.event_channels import EventPlan, RunEvents
from hapticop.observe.log_channel import LogChannel
from hapticop.observe.parameter_events import ParameterEvents
from hapticop.observe.taps import LatestTap, tapped_streams
from hapticop.observe.timing_channels import LoopTiming, TimingPlan
from hapticop.recording.live import LiveOptions, LiveServer, LiveViewUnavailable
from hapticop.recording.mcapfile import RecordingFile, StreamInfo
from hapticop.recording.outputs import Fanout, Output
from hapticop.recording.plan import RecordedStream, recorded_streams
from hapticop.recording.ros2channels import ros2_channels
from hapticop.recording.scene import views_for
from hapticop.runtime.region import Layout, Transport
from hapticop.runtime.streams import SpscQueue, sample_dtype

DRAIN_INTERVAL_NS = 50_000_000  # the recorder wakes 20 times a second (each pass costs ~30 µs a stream
# whatever it finds): a ring holds a second or more
FLUSH_INTERVAL_NS = 1_000_000_000  # a kill loses at most this much, plus one drain
BATCH = 4096  # samples taken from one ring at a time


class View(Protocol):
    """Channels derived from recorded streams (the Foxglove helper's LaserScan, frames...):
    registered when the file is opened, fed the batches of the streams they name as they
    are drained, in the recorder process. Never on a real-time loop."""

    streams: frozenset[str]

    def start(self, file: Output, streams: dict[str, StreamInfo]) -> None: ...

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        """`samples` has `streams.sample_dtype`'s fields; `values(info, samples)` is the arrays."""

    def finish(self) -> None: ...


class Source(Protocol):
    """Channels the recorder fills from elsewhere than a ring (the loops' timing counters, the log
    files), polled at every drain."""

    def start(self, out: Output) -> None: ...

    def poll(self, now_ns: int) -> None: ...

    def finish(self, now_ns: int) -> None: ...


def values(info: StreamInfo, samples: np.ndarray) -> np.ndarray:
    """A drained batch's payloads as the stream's arrays, one per sample."""
    return samples["payload"].view(np.dtype(info.dtype)).reshape((len(samples), *info.shape))


@dataclass(frozen=True)
class RecordedRing:
    """Where a recorded stream's ring lies in the shared region, and what its samples are."""

    info: StreamInfo
    offset: int
    nbytes: int
    capacity: int
    kind: str = "ring"  # or "latest": the stream's own latest slot, tapped for the live view (`taps`)

    def port(self) -> Port:
        return Port(self.info.dtype, self.info.shape, self.info.unit)


@dataclass
class RecorderPlan:
    """All the recorder needs, as plain data a spawned process receives."""

    path: Path | None  # None: nothing written, only shown live
    rings: list[RecordedRing]
    clock: str  # the one clock of every timestamp: 'CLOCK_MONOTONIC' or 'virtual'
    attachments: list[tuple[str, str, bytes]] = field(default_factory=list)  # (name, media type, data)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    views: list = field(default_factory=list)  # `View`s, picklable
    live: LiveOptions | None = None  # serve the channels live too
    timing: TimingPlan | None = None  # the loops' timing counters, for `/timing/THREAD`
    run_dir: Path | None = None  # the run's log files, for `/log`
    name: str = "hapticop"
    events: EventPlan | None = None  # the region's flags and states, for `/events/flags` and `/events/lifecycle`

    @property
    def drain_ns(self) -> int:
        """How often to drain: a tapped slot holds one sample, so as often as the view may send."""
        if self.live is not None and any(ring.kind == "latest" for ring in self.rings):
            return min(DRAIN_INTERVAL_NS, int(1e9 / self.live.rate_hz))
        return DRAIN_INTERVAL_NS


class Recorder:
    """Drains the rings into the file, the live view and the views; one pass per `drain`."""

    def __init__(self, plan: RecorderPlan, rings: dict[str, SpscQueue], clock: Callable[[], int],
                 sources: Sequence[Source] = ()):
        self.plan, self.rings, self.clock = plan, rings, clock
        self.cpu_started = time.process_time()  # in its own process: the recorder's CPU, for the benchmark
        now = self.started_ns = clock()
        self.live, self.view_error = None, None
        if plan.live is not None:  # before the file: a view that cannot listen leaves no file behind
            try:
                self.live = LiveServer(plan.live, plan.name, plan.run_dir)
            except LiveViewUnavailable as error:
                if plan.path is None:
                    raise
                self.view_error = str(error)  # the recording goes on without it
        self.file = RecordingFile(plan.path, library=_library()) if plan.path is not None else None
        outputs: list[Output] = [out for out in (self.file, self.live) if out is not None]
        self.out: Output = outputs[0] if len(outputs) == 1 else Fanout(outputs)
        if self.file is not None:
            for name, media_type, data in plan.attachments:
                self.file.attach(name, media_type, data, now)
            for name, values_ in plan.metadata.items():
                self.file.metadata(name, values_)
        self.streams: dict[str, StreamInfo] = {}
        self.channels: dict[str, int] = {}
        self.batches: dict[str, np.ndarray] = {}
        self.recorded: dict[str, int] = {}
        self.earlier: dict[str, tuple[int, int]] = {}  # (written, dropped) of the rings a stream had before
        for ring in plan.rings:
            self._follow(ring, rings[ring.info.name])
        self.views: Sequence[View] = plan.views
        for view in self.views:
            view.start(self.out, self.streams)
        self.sources = sources
        self.events = [source for source in sources if isinstance(source, RunEvents)]
        for source in sources:
            source.start(self.out)
        if self.file is not None:
            self.file.flush()  # schemas, channels, attachments: on disk before any sample
        self.flushed_ns = now

    def add(self, ring: RecordedRing, queue: SpscQueue) -> None:
        """A stream a live patch added: recorded from now on, on a channel of its own (a stream added
        again after its removal, with the same samples, goes on in the channel it had)."""
        name = ring.info.name
        old = self.rings.get(name)
        if old is not None:  # what its earlier writer left, before the new ring takes its place
            self.drain()
            written, dropped = self.earlier.get(name, (0, 0))
            self.earlier[name] = (written + int(old.written), dropped + int(old.dropped))
            old.close()
        was = self.streams.get(name)
        if was is None or (was.dtype, was.shape) != (ring.info.dtype, ring.info.shape):
            self.channels.pop(name, None)
        self._follow(ring, queue)
        if self.file is not None:
            self.file.flush()

    def _follow(self, ring: RecordedRing, queue: SpscQueue | LatestTap) -> None:
        name = ring.info.name
        self.rings[name] = queue
        if name not in self.channels:
            self.channels[name] = self._stream_channel(ring)
        self.streams[name] = ring.info
        self.batches[name] = np.zeros(min(BATCH, ring.capacity), sample_dtype(ring.port()))
        self.recorded.setdefault(name, 0)

    def _stream_channel(self, ring: RecordedRing) -> int:
        if ring.kind == "latest":  # a tapped slot, read at the display rate already, and never recorded
            return self.live.stream_channel(ring.info, thinned=False)
        return self.out.stream_channel(ring.info)

    @property
    def address(self) -> str | None:
        """Where the live view listens (None: no live view)."""
        return self.live.address if self.live is not None else None

    def drain(self) -> int:
        """Everything the rings hold now; returns how many samples were taken."""
        taken = 0
        for name, ring in self.rings.items():
            batch, info, channel = self.batches[name], self.streams[name], self.channels[name]
            while True:
                n = ring.drain_into(batch)
                if not n:
                    break
                taken += n
                log_time = self.clock()
                samples = batch[:n]
                if info.every > 1:
                    samples = samples[samples["count"] % np.uint64(info.every) == 0]
                self.out.write_samples(channel, samples, log_time)
                self.recorded[name] += len(samples)
                for view in self.views:
                    if name in view.streams:
                        view.samples(info, samples, log_time)
                if n < len(batch):
                    break
        now = self.clock()
        for source in self.sources:
            source.poll(now)
        if self.file is not None and now - self.flushed_ns >= FLUSH_INTERVAL_NS:
            self.file.flush()
            self.flushed_ns = now
        return taken

    def event(self, kind: str, payload: dict, time_ns: int) -> None:
        """Something the run told its observer (`runtime.observer.Observer.event`)."""
        for events in self.events:
            events.event(kind, payload, time_ns)

    def summary(self) -> dict:
        """Per stream: samples its writer published, recorded, and lost (the ring was lapped)."""
        return {"path": str(self.plan.path) if self.file is not None else None, "clock": self.plan.clock,
                "messages": self.file.messages if self.file is not None else 0,
                "view": None if self.live is None else {"address": self.live.public_address, "sent": self.live.sent},
                "view_error": self.view_error, "cpu_s": time.process_time() - self.cpu_started,
                "elapsed_s": (self.clock() - self.started_ns) / 1e9, "streams": {
            name: self._counts(name, ring) for name, ring in self.rings.items()}}

    def _counts(self, name: str, ring: SpscQueue | LatestTap) -> dict[str, int]:
        """A stream's samples written, recorded and dropped, over every ring it had."""
        written, dropped = self.earlier.get(name, (0, 0))
        return {"written": int(ring.written) + written, "recorded": self.recorded[name],
                "dropped": int(ring.dropped) + dropped}

    def finish(self) -> dict:
        """The last samples, the drop counts stored in the file, the file finished and renamed."""
        self.drain()
        for view in self.views:
            view.finish()
        for source in self.sources:
            source.finish(self.clock())
        if self.live is not None:
            self.live.stop()
        summary = self.summary()
        if self.file is None:
            return summary
        streams = summary["streams"]
        self.file.metadata("hapticop.drops", {name: str(s["dropped"]) for name, s in streams.items()})
        self.file.metadata("hapticop.written", {name: str(s["written"]) for name, s in streams.items()})
        self.file.metadata("hapticop.recorder", {
            "cpu_s": f"{summary['cpu_s']:.3f}", "messages": str(self.file.messages),
            "elapsed_s": f"{(self.clock() - self.started_ns) / 1e9:.3f}"})
        summary["path"] = str(self.file.finish())
        return summary


def plan_of(loaded: Loaded, layout: Layout, tree, file: str, path: Path | None, virtual: bool, seed: int = 0,
            run_dir: Path | None = None, live: LiveOptions | None = None) -> RecorderPlan:
    """What a run records (the layout placed the rings), with the composition as it runs (`extends`
    resolved, `--record` applied) and every activity's resolved parameters attached; the loops'
    timing and the log files of `run_dir` beside the streams; served live too with `live`. With no
    file (`path` None) nothing is recorded: every stream's latest slot is tapped for the view."""
    import json
    import platform

    from hapticop.composition.documents import dump

    composition = loaded.composition
    plan = recorded_streams(composition)
    rings = [] if path is not None else [RecordedRing(info, offset, nbytes, 1, "latest")  # shown, not recorded
                                         for info, offset, nbytes in tapped_streams(loaded, layout)]
    rings += [recorded_ring(loaded, transport, plan[name]) for name, transport in layout.recorded.items()]
    params = {name: resolved.params.model_dump(mode="json") for name, resolved in loaded.activities.items()}
    clock = "virtual" if virtual else "CLOCK_MONOTONIC"
    run = {"composition": composition.name or Path(file).stem, "file": str(file), "clock": clock, "seed": str(seed),
           "realtime_minus_clock_ns": str(time.time_ns() - time.monotonic_ns()) if not virtual else "",
           "host": platform.node(), "kernel": platform.release(), "python": platform.python_version(),
           "times": "publish_time: the writing loop's stamp at publication; log_time: when the recorder took the "
                    "sample; sequence: the sample's number (from 1), modulo 2^32"}
    plan = RecorderPlan(path, rings, clock,
                        [("composition.yaml", "application/yaml", dump(tree).encode()),
                         ("parameters.json", "application/json", json.dumps(params, indent=1).encode())],
                        {"hapticop.run": run}, views_for(loaded, [ring.info.name for ring in rings])
                        + (ros2_channels(composition, [ring.info.name for ring in rings], path)
                           if path is not None else []),
                        live,
                        TimingPlan.of(composition, layout), run_dir, run["composition"], events=EventPlan.of(layout))
    plan.rings += [RecordedRing(*ring) for ring in cycle_rings.recorded(loaded, layout)] if path is not None else []
    return plan


def recorded_ring(loaded: Loaded, transport: Transport, recorded: RecordedStream) -> RecordedRing:
    """A recorded stream's ring, with what the file says of its samples."""
    spec = loaded.composition.streams[transport.stream]
    activity, port_name = spec.writer.split(".")
    port = loaded.activities[activity].interface.outputs[port_name]
    info = StreamInfo(transport.stream, np.dtype(port.dtype).name, tuple(port.shape), port.unit, recorded.rate_hz,
                      recorded.every, spec.writer, tuple(spec.readers), spec.doc or port.doc)
    return RecordedRing(info, transport.offset, transport.nbytes, recorded.capacity)


def _library() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return f"hapticop {version('hapticop')}, mcap {version('mcap')}"
    except PackageNotFoundError:
        return "hapticop"


def sources_of(plan: RecorderPlan, buffer) -> list[Source]:
    """The loops' timing, the run's events, its log and its parameter events, as the plan asks."""
    sources: list[Source] = []
    if plan.timing is not None:
        sources.append(LoopTiming(plan.timing, buffer))
    if plan.events is not None:
        sources.append(RunEvents(plan.events, buffer))
    if plan.run_dir is not None:
        sources.append(LogChannel(plan.run_dir))
        sources.append(ParameterEvents(plan.run_dir))
    return sources


def rings_of(plan: RecorderPlan, buffer) -> dict[str, SpscQueue | LatestTap]:
    return {ring.info.name: ring_of(ring, buffer) for ring in plan.rings}


def ring_of(ring: RecordedRing, buffer) -> SpscQueue | LatestTap:
    """The recorder's side of one ring in the region."""
    view = np.ndarray((ring.nbytes,), np.uint8, buffer=buffer, offset=ring.offset)
    return (LatestTap(view, ring.port()) if ring.kind == "latest" else
            SpscQueue(view, ring.port(), ring.capacity, "drop_oldest"))
