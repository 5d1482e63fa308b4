"""The recorder's source of parameter events: what `runtime.parameter_events.landed` wrote to the system's
log, as `/parameters` messages, numbered per activity in the order its runner was handed them."""

from __future__ import annotations

import json
from pathlib import Path

from hapticop.recording import parameters
from hapticop.recording.outputs import Output
from hapticop.runtime.logs import parse_line
from hapticop.runtime.parameter_events import LOG_FILE, PREFIX


class ParameterEvents:
    """A recorder source: the events `landed` wrote to the system's log, as `/parameters` messages."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / LOG_FILE
        self.handle = None
        self.rest = b""
        self.revisions: dict[str, int] = {}
        self.sequence = 0

    def start(self, out: Output) -> None:
        self.out = out
        self.channel: int | None = None  # registered with the first event: a run without any has no channel

    def _channel(self) -> int:
        if self.channel is None:
            schema = self.out.schema("hapticop.ParameterEvent", "jsonschema", json.dumps(parameters.SCHEMA).encode())
            self.channel = self.out.channel(parameters.TOPIC, "json", schema, {"from": str(self.path)})
        return self.channel

    def poll(self, now_ns: int) -> None:
        if self.handle is None:
            if not self.path.exists():
                return
            self.handle = open(self.path, "rb")  # noqa: SIM115 - closed by finish()
        data = self.handle.read()
        if not data:
            return
        lines = (self.rest + data).split(b"\n")
        self.rest = lines.pop()
        for line in lines:
            parsed = parse_line(line.decode("utf-8", "replace"))
            if parsed is None or not parsed[2].startswith(PREFIX):
                continue
            event = json.loads(parsed[2][len(PREFIX):])
            revision = self.revisions[event["activity"]] = self.revisions.get(event["activity"], 0) + 1
            self.sequence += 1
            self.out.write(self._channel(), now_ns, json.dumps({**event, "revision": revision}).encode(), parsed[0],
                           self.sequence)

    def finish(self, now_ns: int) -> None:
        self.poll(now_ns)
        if self.handle is not None:
            self.handle.close()
