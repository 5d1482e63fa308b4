"""A recording read for replay: the composition as it ran, its parameters, its streams, and which of
its activities can be replayed from it.

The composition the run used and every activity's resolved parameters are attached to its
recording (`recorder.plan_of`), and so is every activity's cycles (`runtime.cycle_log`). A recording
is data: its composition resolves built-in blocks only unless trusted, every read is bounded, and
what it lacks is a `ReplayError` naming the file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import ValidationError

from hapticop.blocks.base import Block
from hapticop.blocks.registry import blocks_of_a_recording
from hapticop.composition.diagnostics import Severity
from hapticop.composition.loader import Loaded, load_tree
from hapticop.composition.yamlsource import SourceError, parse_text
from hapticop.recording.mcapfile import StreamInfo
from hapticop.recording.parameters import TOPIC as parameter_events_topic
from hapticop.recording.parameters import ParameterEvent
from hapticop.recording.parameters import events as parameter_events
from hapticop.recording.reading import Contents, RecordingError, Series, contents, series_of
from hapticop.runtime import cycle_log
from hapticop.runtime.assembly import thread_of

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
    trusted: bool = False  # its blocks resolve by any name (`--trust-blocks`), not built-in names only
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
               "hapticop.recorder" in found.metadata, trusted)


# -- which activities ---------------------------------------------------------------------

def inputs_of(run: Run, activity: str) -> list[tuple[str, str]]:
    """(stream, port) of every stream the activity reads."""
    return [(name, reader.split(".")[1]) for name, spec in run.loaded.composition.streams.items()
            for reader in spec.readers if reader.split(".")[0] == activity]


def outputs_of(run: Run, activity: str) -> list[tuple[str, str]]:
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
    for stream, _ in inputs_of(run, activity):
        info = recorded.get(stream)
        if info is None:
            return f"its input stream '{stream}' was not recorded (record it: 'record.streams')"
        if info.every != 1:
            return f"its input stream '{stream}' was recorded only every {info.every}th sample"
        if drops.get(stream):
            return f"its input stream '{stream}' lost {drops[stream]} samples in the recording"
    if not outputs_of(run, activity):
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
    chosen = haptic or [name for name in able if inputs_of(run, name) and not activities[name].block.simulator
                        and not activities[name].block.needs_of(activities[name].params)]
    if not chosen:
        raise ReplayError(f"{run.path}: no activity can be replayed from it (every input of an activity must be "
                          "recorded, undecimated and without drops, and one of its outputs too); name one with "
                          "--activity to hear why")
    return chosen


def resolve_block(run: Run, activity: str) -> type[Block]:
    """The block class of a recorded activity: the one place a replay takes code a recording names."""
    return run.loaded.activities[activity].block


def parameters_of(run: Run, activity: str, block: type[Block]):
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


def same_kind(run: Run, stream: str, what: str, port, info: StreamInfo) -> None:
    if np.dtype(port.dtype) != np.dtype(info.dtype) or tuple(port.shape) != tuple(info.shape):
        raise ReplayError(f"{run.path}: stream '{stream}' was recorded as {info.dtype}{list(info.shape)}, but the "
                          f"{what} takes {np.dtype(port.dtype).name}{list(port.shape)} with the recorded parameters")
