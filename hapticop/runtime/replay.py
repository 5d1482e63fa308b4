"""Replaying a recording: an activity's recorded inputs fed back to its block, its outputs compared.

The composition the run used and every activity's resolved parameters are attached to its
recording (`recorder.plan_of`); a replay builds the chosen activity's block from them with real
ports on a virtual clock, as the runtime would, and steps it through the cycles its thread ran,
in order. Nothing tells the block it is replayed: its input ports read the same transports
(a latest slot, or a queue of the stream's capacity) the runtime gives it, written with the
recorded samples, each with its own number and publication stamp, so `valid`, `age_ns()` and
`seq` say what they said in the run.

How the recorded samples line up with the cycles (docs/recording.md, "Replay"):

- the activity's cycles are the publish times of its recorded outputs (every output a cycle
  publishes carries the cycle's time), with the thread's period filling any gap longer than
  one and a half periods (cycles that published nothing); its creation and resource
  configuration take the two cycles before the first, in which the blocks publish nothing;
- before a cycle at time t, every input sample published before t is written to the port's
  transport, in order; one published at t too when its writer ran earlier at that instant (an
  activity before it in its thread's schedule, or a thread before its own in the file: the
  virtual clock steps equal deadlines in file order); before a flush, the rest published at t;
- the first cycles run the capability configuration until it completes (as the life cycle
  does, the activity runs from the next cycle), then compute (and flush); a run that finished
  in order cleaned its activities, so the last cycle of a block with a `clean` of its own is
  its cleaning;
- flags are not recorded: those the block awaits are held raised, the others lowered.

Under the virtual clock this is the run itself, cycle for cycle, and the outputs are equal to
the bit. A wall-clock recording lines up as well as its stamps allow: a sample another thread
published while the activity computed counts as seen in that cycle.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from pydantic import ValidationError

from hapticop.blocks.base import Block
from hapticop.blocks.registry import blocks_of_a_recording
from hapticop.composition.diagnostics import Severity
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.yamlsource import SourceError, parse_text
from hapticop.recording.compare import Compared, compare
from hapticop.recording.mcapfile import StreamInfo
from hapticop.recording.reading import Contents, RecordingError, Series, contents, series_of
from hapticop.runtime.assembly import activity_rng, thread_of
from hapticop.runtime.clock import VirtualClock
from hapticop.runtime.context import ActivityContext, FlagView, InputPort, OutputPort
from hapticop.runtime.logs import Level, Logger
from hapticop.runtime.streams import LatestSlot, SpscQueue, latest_nbytes, queue_nbytes

DEFAULT_BLOCK = "haptic_controller"  # what `hapticop replay` replays when not told


class ReplayError(Exception):
    """A recording, or an activity of it, that cannot be replayed: the file, and what is wrong."""


@dataclass
class Run:
    """What a replay reads of a recording: the composition as it ran, its parameters, its streams."""

    path: Path
    found: Contents
    loaded: Loaded
    parameters: dict
    virtual: bool
    seed: int
    finished: bool  # the run ended in order: its activities were cleaned
    _series: dict[str, Series] = field(default_factory=dict)

    @property
    def streams(self) -> dict[str, StreamInfo]:
        """The recorded raw streams, by name."""
        return {c.stream.name: c.stream for c in self.found.channels if c.stream is not None}

    def load(self, streams: list[str]) -> None:
        """Read these streams' samples, those not read yet, in one pass over the file."""
        missing = [s for s in dict.fromkeys(streams) if s not in self._series]
        if missing:
            try:
                self._series.update(series_of(self.path, missing))
            except RecordingError as error:
                raise ReplayError(str(error)) from None

    def series(self, stream: str) -> Series:
        self.load([stream])
        return self._series[stream]


MAX_NESTING = 64  # an attachment nesting deeper is not one hapticop wrote (as `yamlsource.MAX_NESTING`)


def _nesting(text: str) -> int:
    """How deep the text's brackets and braces nest, quoted strings left out, without parsing it:
    the JSON and YAML parsers recurse, so a 100,000-deep file must be turned away before them."""
    import re

    depth = deepest = 0
    for mark in re.sub(r'"(?:[^"\\]|\\.)*"|\'(?:[^\']|\'\')*\'', "", text):
        if mark in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif mark in "]}":
            depth -= 1
    return deepest


def open_run(path: Path, trusted: bool = False) -> Run:
    """A recording read for replay; a `ReplayError` says what it lacks.

    Its composition is data: only built-in blocks resolve unless `trusted` (`--trust-blocks`),
    and even then no module comes from the recording's folder (`blocks_of_a_recording`)."""
    path = Path(path)
    try:
        found = contents(path)
    except RecordingError as error:
        raise ReplayError(str(error)) from None
    attached = found.attachments
    for name in ("composition.yaml", "parameters.json"):
        if name not in attached:
            raise ReplayError(f"{path}: no {name} attached: the recording does not say what ran, so there is "
                              "nothing to replay against")
    try:
        text = attached["composition.yaml"].decode()
        if _nesting(text) > MAX_NESTING:
            raise ReplayError(f"{path}: its attached composition.yaml nests deeper than {MAX_NESTING} levels")
        source = parse_text(text, f"{path}:composition.yaml")
    except (SourceError, UnicodeDecodeError) as error:
        raise ReplayError(f"{path}: its attached composition does not read: {error}") from None
    with blocks_of_a_recording(trusted, path.parent):
        loaded = load_tree(source.tree)
    errors = [d for d in loaded.diagnostics if d.severity is Severity.ERROR]
    if loaded.composition is None or errors:
        what = errors[0].message if errors else "no composition"
        hint = next((d.hint for d in errors if "--trust-blocks" in (d.hint or "")), "")
        raise ReplayError(f"{path}: its attached composition does not load here: {what}{'; ' + hint if hint else ''}")
    try:
        text = attached["parameters.json"].decode()
        if _nesting(text) > MAX_NESTING:
            raise ReplayError(f"{path}: its attached parameters.json nests deeper than {MAX_NESTING} levels")
        parameters = json.loads(text)
    except ValueError as error:
        raise ReplayError(f"{path}: its attached parameters.json is not JSON ({error})") from None
    if not isinstance(parameters, dict):
        raise ReplayError(f"{path}: its attached parameters.json is not a mapping of activities to parameters")
    run = found.metadata.get("hapticop.run", {})
    try:
        seed = int(run.get("seed") or 0)
    except ValueError:
        raise ReplayError(f"{path}: its run metadata has a seed that is not a number: {run.get('seed')!r}") from None
    return Run(path, found, loaded, parameters, run.get("clock") == "virtual", seed,
               "hapticop.recorder" in found.metadata)


# -- which activities ---------------------------------------------------------------------

def _inputs_of(run: Run, activity: str) -> list[tuple[str, str]]:
    """(stream, port) of every stream the activity reads."""
    return [(name, reader.split(".")[1]) for name, spec in run.loaded.composition.streams.items()
            for reader in spec.readers if reader.split(".")[0] == activity]


def _outputs_of(run: Run, activity: str) -> list[tuple[str, str]]:
    """(stream, port) of every recorded stream the activity writes."""
    recorded = run.streams
    return [(name, spec.writer.split(".")[1]) for name, spec in run.loaded.composition.streams.items()
            if spec.writer.split(".")[0] == activity and name in recorded]


def why_not(run: Run, activity: str) -> str | None:
    """Why the activity cannot be replayed from this recording, or None if it can."""
    if activity not in thread_of(run.loaded.composition):
        return "it is on no thread's schedule"
    recorded, drops = run.streams, run.found.drops()
    for stream, _ in _inputs_of(run, activity):
        info = recorded.get(stream)
        if info is None:
            return f"its input stream '{stream}' was not recorded (record it: 'record.streams')"
        if info.every != 1:
            return f"its input stream '{stream}' was recorded only every {info.every}th sample"
        if drops.get(stream):
            return f"its input stream '{stream}' lost {drops[stream]} samples in the recording"
    if not _outputs_of(run, activity):
        return "none of its output streams was recorded: there is nothing to compare"
    return None


def choose(run: Run, wanted: list[str]) -> list[str]:
    """The activities named (each checked), or by default the haptic controllers, or else every
    activity with inputs, all recorded, that needs no other activity and is no simulator."""
    activities = run.loaded.activities
    for name in wanted:
        if name not in activities:
            raise ReplayError(f"{run.path}: the recorded composition has no activity '{name}' "
                              f"(it has: {', '.join(activities)})")
        reason = why_not(run, name)
        if reason:
            raise ReplayError(f"{run.path}: activity '{name}' cannot be replayed: {reason}")
    if wanted:
        return list(wanted)
    able = [name for name in activities if why_not(run, name) is None]
    haptic = [name for name in able if activities[name].spec.block == DEFAULT_BLOCK]
    chosen = haptic or [name for name in able if _inputs_of(run, name) and not activities[name].block.simulator
                        and not activities[name].block.needs_of(activities[name].params)]
    if not chosen:
        raise ReplayError(f"{run.path}: no activity can be replayed from it (every input of an activity must be "
                          "recorded, undecimated and without drops, and one of its outputs too); name one with "
                          "--activity to hear why")
    return chosen


# -- one activity, replayed ----------------------------------------------------------------

class _Discard:
    """A log sink: what a replayed block says is not the replay's business."""

    @staticmethod
    def put(_item) -> None:
        return None


@dataclass
class _Feed:
    """One input stream's recorded samples, written to the port's transport as their time comes."""

    stream: str
    write: Callable[[np.ndarray, int], object]
    samples: Series
    first: bool  # a sample stamped at a cycle's time was written before the activity ran in it
    local: bool  # written on the activity's own thread
    next: int = 0

    def latest(self, t_ns: int) -> int | None:
        """The stamp of the last sample published at or before `t_ns`."""
        i = int(np.searchsorted(self.samples.publish_ns, t_ns, side="right")) - 1
        return int(self.samples.publish_ns[i]) if i >= 0 else None

    def until(self, t_ns: int, inclusive: bool) -> None:
        publish, values = self.samples.publish_ns, self.samples.values
        i, n = self.next, len(publish)
        while i < n and (publish[i] < t_ns or (inclusive and publish[i] == t_ns)):
            self.write(values[i], int(publish[i]))
            i += 1
        self.next = i


class _Captured:
    """An output's transport that keeps every published sample and its stamp."""

    def __init__(self) -> None:
        self.values: list[np.ndarray] = []
        self.stamps: list[int] = []

    def push(self, value: np.ndarray, stamp_ns: int, origins=None) -> None:
        self.values.append(np.array(value, copy=True))
        self.stamps.append(int(stamp_ns))


@dataclass
class Replayed:
    """One activity's replay."""

    activity: str
    block: str
    thread: str
    cycles: int
    start_s: float
    end_s: float
    inputs: list[str]
    compared: list[Compared]

    @property
    def ok(self) -> bool:
        return all(c.ok for c in self.compared)


class ActivityReplay:
    """The activity's block with real ports on a virtual clock, fed from the recording."""

    def __init__(self, run: Run, activity: str, run_dir: Path):
        self.run, self.name = run, activity
        composition = run.loaded.composition
        resolved = run.loaded.activities[activity]
        self.block_type = resolved.block
        params = _parameters(run, activity, resolved.block)
        interface = resolved.block.declare(params)
        self.thread = thread_of(composition)[activity]
        self.period = composition.threads[self.thread].period
        self.on_request = resolved.spec.start == "on_request"
        self.clock = VirtualClock()
        now = self.clock.now_ns
        inputs = {p: InputPort(p, spec, now) for p, spec in interface.inputs.items()}
        outputs = {p: OutputPort(p, spec, now) for p, spec in interface.outputs.items()}
        self.feeds: list[_Feed] = []
        run.load([stream for stream, _ in _inputs_of(run, activity) + _outputs_of(run, activity)])
        for stream, port in _inputs_of(run, activity):
            spec = composition.streams[stream]
            port_spec = interface.inputs[port]
            samples = run.series(stream)
            _same_kind(run, stream, f"input '{port}'", port_spec, samples.info)
            if spec.policy.kind == "queue":
                capacity = spec.policy.capacity
                transport = SpscQueue(bytearray(queue_nbytes(port_spec, capacity)), port_spec, capacity,
                                      spec.policy.overflow)
                write = transport.push
            else:
                transport = LatestSlot(bytearray(latest_nbytes(port_spec)), port_spec, synchronised=False)
                write = transport.write
            inputs[port].connect(transport, spec.policy.kind == "queue", spec.max_age or 0)
            writer = spec.writer.split(".")[0]
            self.feeds.append(_Feed(stream, write, samples, self._runs_first(writer),
                                    thread_of(composition).get(writer) == self.thread))
        self.outputs: list[tuple[str, str, _Captured, Series]] = []
        for stream, port in _outputs_of(run, activity):
            recorded = run.series(stream)
            _same_kind(run, stream, f"output '{port}'", interface.outputs[port], recorded.info)
            captured = _Captured()
            outputs[port].transports.append(captured)
            self.outputs.append((stream, port, captured, recorded))
        run_dir.mkdir(parents=True, exist_ok=True)
        self.context = _context(run, activity, params, interface, self.clock, run_dir, inputs, outputs, self.period)
        self.ports = list(inputs.values())
        self.run_dir = run_dir
        self.needs = [need.activity for need in resolved.block.needs_of(params)
                      if need.activity in run.loaded.activities]
        self.block = self._hook("building", lambda: resolved.block(self.context))

    def _runs_first(self, writer: str) -> bool:
        """Whether the writer runs before this activity at an instant both run at."""
        composition = self.run.loaded.composition
        owner = thread_of(composition)
        theirs = owner.get(writer)
        if theirs != self.thread:
            order = list(composition.threads)
            return theirs is not None and order.index(theirs) < order.index(self.thread)
        for members in composition.threads[self.thread].schedules.values():
            if writer in members and self.name in members:
                return members.index(writer) < members.index(self.name)
        return False

    def cycles(self) -> tuple[np.ndarray, np.ndarray]:
        """The times of the activity's cycles, and which of them published a recorded output."""
        published = [recorded.publish_ns for _, _, _, recorded in self.outputs]
        if not any(len(p) for p in published):
            raise ReplayError(f"{self.run.path}: activity '{self.name}' published no recorded sample: "
                              "there is nothing to compare")
        if not self.run.virtual:
            # One cycle's outputs are stamped microseconds apart, and a gap is an overrun's skipped
            # periods: the cycles are those of the output published most often, as they were stamped.
            stamps = max(published, key=len)
            return stamps.astype(np.int64), np.ones(len(stamps), bool)
        stamps = np.unique(np.concatenate(published))
        period = self.period
        times, marks = [], []
        for i, t in enumerate(stamps):
            if i:  # cycles that published nothing (or decimated outputs): on the thread's period
                gap = int(t - stamps[i - 1])
                filled = int(round(gap / period)) - 1 if gap > 1.5 * period else 0
                for k in range(1, filled + 1):
                    times.append(int(stamps[i - 1]) + k * period)
                    marks.append(False)
            times.append(int(t))
            marks.append(True)
        return np.asarray(times, np.int64), np.asarray(marks, bool)

    def _at(self, t_ns: int, inclusive_all: bool = False) -> None:
        """The clock at `t_ns`, the samples due by then written, the inputs refreshed.

        On the wall clock a cycle is known by its outputs' stamps, taken after it computed: another
        thread's sample stamped between its start and then was not seen. Its start is bounded by the
        last sample an activity before it on its thread published in the cycle (the Falcon's handle,
        for the haptic controller): another thread's samples count up to that stamp."""
        self.clock.advance_to(max(t_ns, self.clock.now_ns()))
        seen_by = t_ns
        if not self.run.virtual and not inclusive_all:
            stamps = [feed.latest(t_ns) for feed in self.feeds if feed.local and feed.first]
            started = [stamp for stamp in stamps if stamp is not None and stamp > t_ns - self.period]
            seen_by = max(started, default=t_ns)
        for feed in self.feeds:
            if feed.local or inclusive_all:
                feed.until(t_ns, inclusive_all or feed.first)
            else:
                feed.until(seen_by, seen_by != t_ns or feed.first)
        for port in self.ports:
            port.refresh()

    def _hook(self, what: str, call: Callable[[], object]) -> object:
        try:
            return call()
        except Exception as error:  # noqa: BLE001 - a block's failure is the replay's finding, not a traceback
            raise ReplayError(f"{self.run.path}: activity '{self.name}': its {what} raised at "
                              f"{self.clock.now_ns() / 1e9:.6f} s: {type(error).__name__}: {error}") from None

    def _configure(self, capabilities_at: int) -> bool:
        """Create and configure the block in the cycles before `capabilities_at`, capabilities there;
        whether they completed."""
        block, period = self.block, self.period
        self._at(capabilities_at - 2 * period)
        self._hook("create", block.create)
        self._at(capabilities_at - period)
        if self._hook("configure_resources", block.configure_resources) is False:
            raise ReplayError(f"{self.run.path}: activity '{self.name}': its resource configuration does not "
                              "complete with the flags it awaits raised: replay cannot tell when it did")
        self._at(capabilities_at)
        return self._hook("configure_capabilities", block.configure_capabilities) is not False

    def _probe(self, at: int) -> tuple[bool, bool]:
        """Whether the capability configuration publishes (the haptic controller holds the handle while
        it waits) and whether cleaning does (it zeroes the force), found on a block of its own in a
        scratch directory: the first recorded output is the configuration's or the first compute's,
        the last the cleaning's or the last compute's."""
        import tempfile

        with tempfile.TemporaryDirectory(prefix="hapticop-replay-") as scratch:
            probe = ActivityReplay(self.run, self.name, Path(scratch))
            beside = [_beside(self.run, name, probe.clock, Path(scratch)) for name in probe.needs]

            def published() -> int:
                return sum(len(captured.values) for _, _, captured, _ in probe.outputs)

            probe._configure(at)
            configuring = published()
            try:
                probe.block.clean()
            except Exception:  # noqa: BLE001 - a block that cannot clean this early: it is not the cleaning that published
                pass
            cleaning = published() - configuring
            for other in beside:
                other.clean()
        return configuring > 0, cleaning > 0

    def replay(self, tolerance: float = 0.0) -> Replayed:
        times, published = self.cycles()
        period, block = self.period, self.block
        start = int(times[0])
        beside = [_beside(self.run, name, self.clock, self.run_dir) for name in self.needs]
        configuring_publishes, cleaning_publishes = self._probe(start)
        if configuring_publishes:
            configured, first = self._configure(start), 1
        else:
            configured, first = self._configure(start - period), 0
            if not configured:
                raise ReplayError(f"{self.run.path}: activity '{self.name}': its capability configuration publishes "
                                  "nothing and does not complete at once: replay cannot tell when it did")
        running = configured and not self.on_request
        failed = False
        flushes = self.block_type.implements_flush()
        cleans = self.run.finished and cleaning_publishes
        last = len(times) - 1
        for i, t in enumerate(times):
            if i < first:
                continue
            if configured and not running and not published[i]:
                continue  # started on request: ready, waiting for the mediator's word
            self._at(int(t))
            if not configured:
                configured = self._hook("configure_capabilities", block.configure_capabilities) is not False
                running = configured and not self.on_request
                continue
            running = True
            if i == last and cleans:
                self._hook("clean", block.clean)
                break
            if failed:  # a running hook raised in the run as here: the life cycle paused it
                self._hook("pausing", block.pausing)
                continue
            try:
                block.compute()
                if flushes:
                    self._at(int(t), inclusive_all=True)
                    block.flush()
            except Exception:  # noqa: BLE001 - as the life cycle: the activity pauses, its outputs safe
                failed = True
        if self.run.finished and not cleans:  # cleaned after its last output, publishing nothing
            self._at(int(times[-1]) + period)
            self._hook("clean", block.clean)
        for other in beside:
            other.clean()
        origin = min((int(s.samples.publish_ns[0]) for s in self.feeds if len(s.samples.publish_ns)), default=start)
        origin = min(origin, start)
        compared = [compare(stream, port, captured.values, captured.stamps, recorded, tolerance, self.run.virtual,
                            origin)
                    for stream, port, captured, recorded in self.outputs]
        return Replayed(self.name, self.run.loaded.activities[self.name].spec.block, self.thread, len(times),
                        (start - origin) / 1e9, (int(times[-1]) - origin) / 1e9,
                        [feed.stream for feed in self.feeds], compared)


def _beside(run: Run, activity: str, clock: VirtualClock, run_dir: Path) -> Block:
    """An activity the replayed one needs (an operator a world judges, say), created and
    resource-configured with no ports connected, so that what it tells its run (`hapticop.published`)
    is there as it was; it is never stepped."""
    resolved = run.loaded.activities[activity]
    params = _parameters(run, activity, resolved.block)
    interface = resolved.block.declare(params)
    context = _context(run, activity, params, interface, clock, run_dir,
                       {p: InputPort(p, spec, clock.now_ns) for p, spec in interface.inputs.items()},
                       {p: OutputPort(p, spec, clock.now_ns) for p, spec in interface.outputs.items()}, 0)
    try:
        block = resolved.block(context)
        block.create()
        block.configure_resources()
    except Exception as error:  # noqa: BLE001
        raise ReplayError(f"{run.path}: activity '{activity}', needed beside the replayed one, does not configure "
                          f"outside its run: {type(error).__name__}: {error}") from None
    return block


def _context(run: Run, activity: str, params, interface, clock: VirtualClock, run_dir: Path, inputs: dict,
             outputs: dict, period_ns: int) -> ActivityContext:
    """What the block sees, as the runtime gives it: its flags (those it awaits raised), a log
    nobody reads, the run's randomness for this activity."""
    names = list(interface.flags_written) + list(interface.flags_read)
    awaited = run.loaded.activities[activity].block.awaits
    flags = np.array([flag in awaited for flag in names] or [False], np.uint8)
    view = FlagView(flags, {f"{activity}.{flag}": i for i, flag in enumerate(names)}, activity, names)
    log = Logger(activity, Level.ERROR, _Discard(), clock.now_ns)  # type: ignore[arg-type]
    return ActivityContext(activity, params, SimpleNamespace(**inputs), SimpleNamespace(**outputs), view, clock, log,
                           activity_rng(run.seed, activity), run_dir, period_ns=period_ns)


def _parameters(run: Run, activity: str, block: type[Block]):
    raw = run.parameters.get(activity)
    if not isinstance(raw, dict):
        raise ReplayError(f"{run.path}: its attached parameters.json has no parameters for activity '{activity}'")
    try:
        return block.Params.model_validate(raw)
    except ValidationError as error:
        first = error.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        raise ReplayError(f"{run.path}: parameters.json, activity '{activity}', {where or 'parameters'}: "
                          f"{first['msg']}") from None


def _same_kind(run: Run, stream: str, what: str, port, info: StreamInfo) -> None:
    if np.dtype(port.dtype) != np.dtype(info.dtype) or tuple(port.shape) != tuple(info.shape):
        raise ReplayError(f"{run.path}: stream '{stream}' was recorded as {info.dtype}{list(info.shape)}, but the "
                          f"{what} takes {np.dtype(port.dtype).name}{list(port.shape)} with the recorded parameters")


def replay(path: Path, activities: list[str] | None = None, tolerance: float = 0.0,
           run_dir: Path | None = None, trusted: bool = False) -> list[Replayed]:
    """Replay the chosen activities of a recording, each from its own recorded inputs."""
    import tempfile

    run = open_run(path, trusted)
    chosen = choose(run, list(activities or []))
    with tempfile.TemporaryDirectory(prefix="hapticop-replay-") as scratch:
        base = Path(run_dir) if run_dir is not None else Path(scratch)
        return [ActivityReplay(run, name, base).replay(tolerance) for name in chosen]


def leaving_results(run: Run) -> list[str]:
    """The activities whose blocks leave files in the run directory when they clean (`promises`)."""
    return [name for name, resolved in run.loaded.activities.items() if resolved.block.promises(resolved.params)]


def results(path: Path | Run, run_dir: Path, tolerance: float = 0.0) -> tuple[list[Replayed], list[Path]]:
    """What the run's activities leave when they clean (the hallway world's trajectory, metrics and
    picture), made again from the recording: every activity whose block promises files is
    replayed into `run_dir`. Returns the replays and the files they left."""
    run = path if isinstance(path, Run) else open_run(path)
    activities = run.loaded.activities
    promising = leaving_results(run)
    if not promising:
        raise ReplayError(f"{run.path}: no activity of its composition leaves results (a block whose "
                          "`promises` names files, such as hallway_world)")
    reasons = {name: why_not(run, name) for name in promising}
    able = [name for name, reason in reasons.items() if reason is None]
    if not able:
        name, reason = next(iter(reasons.items()))
        raise ReplayError(f"{run.path}: activity '{name}' cannot be replayed: {reason}")
    run_dir = Path(run_dir)
    replayed = [ActivityReplay(run, name, run_dir).replay(tolerance) for name in able]
    files = [run_dir / f for name in able for f in activities[name].block.promises(activities[name].params)
             if (run_dir / f).exists()]
    return replayed, files
