"""Replaying a recording: an activity's recorded inputs fed back to its block, its outputs compared.

The composition the run used and every activity's resolved parameters are attached to its
recording (`recorder.plan_of`), and so is every activity's cycles (`runtime.cycle_log`: per step,
its time, the LCSM state, requests and flags it started from, and the number of the sample each
input held). A replay builds the chosen activity's block from them on the runtime's own runner
and life cycle (`runtime.alone`), with real ports on a virtual clock, and steps it once per
recorded cycle, in order: the clock at the cycle's time, its requests and flags as they were,
each input's transport (a latest slot, or a queue of the stream's capacity) written with the
recorded samples up to the one the cycle saw, each with its own number and stamp, so `valid`,
`age_ns()` and `seq` say what they said in the run. Nothing tells the block it is replayed.

Cycles a wall-clock run missed were never stepped, so they are not replayed either; samples
another thread published while the activity computed are not seen before the cycle that saw
them. Under the virtual clock and on the wall clock alike the outputs come back equal to the bit
(docs/recording.md, "Replay").
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from hapticop.blocks.base import Block
from hapticop.blocks.registry import blocks_of_a_recording
from hapticop.composition.diagnostics import Severity
from hapticop.composition.lcsm import State
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.yamlsource import SourceError, parse_text
from hapticop.recording.compare import Compared, compare
from hapticop.recording.mcapfile import StreamInfo
from hapticop.recording.parameters import TOPIC as parameter_events_topic
from hapticop.recording.parameters import ParameterEvent
from hapticop.recording.parameters import events as parameter_events
from hapticop.recording.reading import Contents, RecordingError, Series, contents, series_of
from hapticop.runtime import cycle_log
from hapticop.runtime.alone import Alone, alone
from hapticop.runtime.assembly import activity_rng, thread_of
from hapticop.runtime.clock import VirtualClock
from hapticop.runtime.logs import Level, Logger
from hapticop.runtime.streams import LatestSlot, SpscQueue, latest_nbytes, queue_nbytes

DEFAULT_BLOCK = "haptic_controller"  # what `hapticop replay` replays when not told
BESIDE_CYCLES = 1000  # cycles an activity needed beside the replayed one may take to configure its resources


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
    _events: list[ParameterEvent] | None = None

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

    def parameter_events(self) -> list[ParameterEvent]:
        """The parameters handed to running activities, in order (`recording.parameters`)."""
        if self._events is None:
            try:
                self._events = parameter_events(self.path)
            except (OSError, ValueError, KeyError) as error:
                raise ReplayError(f"{self.path}: its {parameter_events_topic} do not read: {error}") from None
        return self._events

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
    cycles = cycle_log.stream_of(activity)
    if cycles not in recorded:
        return f"its cycles ('{cycles}') were not recorded: the recording says nothing of what each cycle saw"
    if drops.get(cycles):
        return f"its cycles ('{cycles}') lost {drops[cycles]} rows in the recording"
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


class _Feed:
    """One input stream's recorded samples, written to the port's transport up to a number."""

    def __init__(self, stream: str, write: Callable[[np.ndarray, int], object], samples: Series):
        self.stream, self.write, self.samples = stream, write, samples
        self.next = 0  # samples written: the next one's number is this plus one

    def up_to(self, number: int) -> None:
        """Every sample up to the one numbered `number` written, in order, each with its stamp (the
        transport numbers them as the run's did: every sample is recorded, none lost)."""
        values, publish = self.samples.values, self.samples.publish_ns
        end = min(int(number), len(values))
        for i in range(self.next, end):
            self.write(values[i], int(publish[i]))
        self.next = max(self.next, end)


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
    cycles: int  # replayed: every recorded step of the activity, configuring and cleaning too
    start_s: float
    end_s: float
    inputs: list[str]
    compared: list[Compared]
    diverged: str = ""  # where the replayed life cycle left the recorded one, in words
    computed: int = 0  # cycles that ran the block's compute

    @property
    def ok(self) -> bool:
        return not self.diverged and all(c.ok for c in self.compared)


class ActivityReplay:
    """The activity's block on the runtime's runner (`runtime.alone`), on a virtual clock set to each
    recorded cycle's time, its inputs holding the samples the recorded cycle saw."""

    def __init__(self, run: Run, activity: str, run_dir: Path):
        self.run, self.name = run, activity
        composition = run.loaded.composition
        resolved = run.loaded.activities[activity]
        self.block_type = resolve_block(run, activity)
        params = _parameters(run, activity, self.block_type)
        interface = self.block_type.declare(params)
        self.thread = thread_of(composition)[activity]
        self.period = composition.threads[self.thread].period
        self.clock = VirtualClock()
        run_dir.mkdir(parents=True, exist_ok=True)
        self.run_dir = run_dir
        run.load([stream for stream, _ in _inputs_of(run, activity) + _outputs_of(run, activity)]
                 + [cycle_log.stream_of(activity)])
        self.rows = run.series(cycle_log.stream_of(activity))
        flushes = self.block_type.implements_flush()
        expected = cycle_log.columns(interface, flushes)
        if json.loads(self.rows.info.doc or "[]") != expected:
            raise ReplayError(f"{run.path}: activity '{activity}': its recorded cycles do not have the columns its "
                              f"block declares with the recorded parameters ({', '.join(expected)})")
        self.needs = [need.activity for need in self.block_type.needs_of(params)
                      if need.activity in run.loaded.activities]
        self.beside: list[Alone] = []
        log = Logger(activity, Level.ERROR, _Discard(), self.clock.now_ns)  # type: ignore[arg-type]
        try:
            self.alone = alone(activity, self.block_type, params, self.clock, run_dir, activity_rng(run.seed, activity),
                               log, log, period_ns=self.period, start_on_request=resolved.spec.start == "on_request")
        except Exception as error:  # noqa: BLE001 - a block's failure is the replay's finding, not a traceback
            raise ReplayError(f"{run.path}: activity '{activity}': its building raised: "
                              f"{type(error).__name__}: {error}") from None
        inputs, outputs = self.alone.context.inputs, self.alone.context.outputs
        self.feeds: list[_Feed] = []
        for stream, port in _inputs_of(run, activity):
            spec = composition.streams[stream]
            port_spec = interface.inputs[port]
            samples = run.series(stream)
            _same_kind(run, stream, f"input '{port}'", port_spec, samples.info)
            if spec.policy.kind == "queue":
                capacity = spec.policy.capacity
                transport = SpscQueue(bytearray(queue_nbytes(port_spec, capacity)), port_spec, capacity,
                                      spec.policy.overflow)
            else:
                transport = LatestSlot(bytearray(latest_nbytes(port_spec)), port_spec, synchronised=False)
            getattr(inputs, port).connect(transport, spec.policy.kind == "queue", spec.max_age or 0)
            self.feeds.append(_Feed(stream, transport.push, samples))
        self.by_port = {port: feed for (_, port), feed in zip(_inputs_of(run, activity), self.feeds, strict=True)}
        self.outputs: list[tuple[str, str, _Captured, Series]] = []
        for stream, port in _outputs_of(run, activity):
            recorded = run.series(stream)
            _same_kind(run, stream, f"output '{port}'", interface.outputs[port], recorded.info)
            captured = _Captured()
            getattr(outputs, port).transports.append(captured)
            self.outputs.append((stream, port, captured, recorded))
        self.columns = {name: i for i, name in enumerate(expected)}
        self.flag_indices = [self.alone.region.layout.flag_index[f"{activity}.lcsm.{name[8:]}" if
                                                                 name.startswith("request.") else
                                                                 f"{activity}.{name[5:]}"]
                             for name in expected if name.startswith(("request.", "flag."))]
        self.inputs = [name.split(".", 1)[1] for name in expected if name.startswith("step.")]

    def _feed(self, row: np.ndarray, phase: str) -> None:
        for port in self.inputs:
            feed = self.by_port.get(port)
            if feed is not None:
                feed.up_to(int(row[self.columns[f"{phase}.{port}"]]))

    def replay(self, tolerance: float = 0.0) -> Replayed:
        """Every recorded cycle again, in order: the clock at its time, its requests and flags as they
        were, its inputs holding the samples it saw; then the outputs compared with the recorded ones."""
        times, rows = self.rows.publish_ns, self.rows.values
        if not len(times):
            raise ReplayError(f"{self.run.path}: activity '{self.name}' recorded no cycle: there is nothing to replay")
        runner, flags, states = self.alone.runner, self.alone.region.flags, self.alone.region.state
        first_flag = 2
        diverged = ""
        computed: list[int] = []  # the cycles that ran the block's compute
        handed = 0  # the parameter events handed to the runner so far
        self.beside = [_beside(self.run, name, self.clock, self.run_dir) for name in self.needs]
        try:
            for t, row in zip(times, rows, strict=True):
                self.clock.advance_to(max(int(t), self.clock.now_ns()))
                if int(states[0]) != int(row[0]) and not diverged:
                    diverged = (f"at {self._at(int(t)):.6f} s the run's life cycle was "
                                f"{State(int(row[0])).flag_name}, the replay's {State(int(states[0])).flag_name}")
                if int(row[1]) != handed:
                    handed = self._hand(int(row[1]), handed, int(t))
                for k, index in enumerate(self.flag_indices):
                    flags[index] = row[first_flag + k]
                self._feed(row, "step")
                runner.step()
                if runner.computing:
                    computed.append(int(t))
                if runner.flushes:
                    self._feed(row, "flush")
                    runner.flush()
        finally:
            for other in self.beside:  # cleaned by its life cycle, as a run's shutdown cleans it
                other.runner.lifecycle.request_cleaning()
                other.runner.step()
                other.close()
            self.alone.close()
        start, end = int(times[0]), int(times[-1])
        origin = min([int(f.samples.publish_ns[0]) for f in self.feeds if len(f.samples.publish_ns)] + [start])
        compared = [compare(stream, port, captured.values, captured.stamps, recorded, tolerance, self.run.virtual,
                            origin)
                    for stream, port, captured, recorded in self.outputs]
        return Replayed(self.name, self.run.loaded.activities[self.name].spec.block, self.thread, len(times),
                        (start - origin) / 1e9, (end - origin) / 1e9,
                        [feed.stream for feed in self.feeds], compared, diverged, len(computed))

    def _hand(self, revision: int, handed: int, t_ns: int) -> int:
        """The parameters the run's block held from this cycle on handed to the runner, as the run handed
        them (events the run handed between two steps arrive as one, the names changed by any)."""
        events = {event.revision: event for event in self.run.parameter_events() if event.activity == self.name}
        wanted = range(handed + 1, revision + 1)
        missing = [n for n in wanted if n not in events]
        if missing or revision < handed:
            raise ReplayError(f"{self.run.path}: activity '{self.name}' held parameter set {revision} from "
                              f"{self._at(t_ns):.6f} s, but the recording's {parameter_events_topic} has no event "
                              f"{missing[0] if missing else revision} for it")
        event = events[revision]
        try:
            params = self.block_type.Params.model_validate(event.parameters)
        except ValidationError as error:
            raise ReplayError(f"{self.run.path}: {parameter_events_topic}, activity '{self.name}', revision "
                              f"{revision}: {error.errors()[0]['msg']}") from None
        changed = frozenset(name for n in wanted for name in events[n].changed)
        self.alone.runner.retune(params, changed)
        return revision

    def _at(self, t_ns: int) -> float:
        origin = min([int(f.samples.publish_ns[0]) for f in self.feeds if len(f.samples.publish_ns)]
                     + [int(self.rows.publish_ns[0])])
        return (t_ns - origin) / 1e9


def _beside(run: Run, activity: str, clock: VirtualClock, run_dir: Path) -> Alone:
    """An activity the replayed one needs (an operator a world judges, say), on a runner of its own
    stepped through creation and resource configuration with no ports connected, so that what it
    tells its run (`hapticop.published`) is there as it was; it is never run."""
    block_type = resolve_block(run, activity)
    params = _parameters(run, activity, block_type)
    log = Logger(activity, Level.ERROR, _Discard(), clock.now_ns)  # type: ignore[arg-type]
    try:
        one = alone(activity, block_type, params, clock, run_dir, activity_rng(run.seed, activity), log, log)
    except Exception as error:  # noqa: BLE001
        raise ReplayError(f"{run.path}: activity '{activity}', needed beside the replayed one, cannot be built: "
                          f"{type(error).__name__}: {error}") from None
    for _ in range(BESIDE_CYCLES):
        if one.state is State.CAPABILITY_CONFIGURATION:
            return one
        one.runner.step()
        error = one.failure()
        if error is not None:
            break
    else:
        error = None
    one.close()
    why = f"{type(error).__name__}: {error}" if error is not None else f"not within {BESIDE_CYCLES} cycles"
    raise ReplayError(f"{run.path}: activity '{activity}', needed beside the replayed one, does not configure "
                      f"outside its run: {why}")


def resolve_block(run: Run, activity: str) -> type[Block]:
    """The block class of a recorded activity: the one place a replay takes code a recording names."""
    return run.loaded.activities[activity].block


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
