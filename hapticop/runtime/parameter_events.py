"""Parameter events: each new parameter set an activity is handed while running, recorded as `/parameters`.

Where new parameters land (`live.retune`, for a patch and a mode alike) says so in the system's
log, off the real-time path (`logs.LogWriter`); the recorder follows that file and writes each
event, numbered per activity in the order they were handed, as the runner numbers them
(`ActivityRunner.parameters`), so a replay knows from an activity's recorded cycles which set
its block held in each one.
"""

from __future__ import annotations

import json
from pathlib import Path

from hapticop.recording import parameters
from hapticop.recording.outputs import Output
from hapticop.runtime.logs import Logger, parse_line

PREFIX = "parameters handed: "
LOG_FILE = "system.log"  # the owner whose logger `landed` is given (`System.log`)


def landed(log: Logger, activity: str, params, changed: frozenset[str]) -> None:
    """New parameters handed to `activity` (its runner numbers them in the same order)."""
    dumped = params.model_dump(mode="json")
    log.info("%s%s", PREFIX, json.dumps({"activity": activity, "parameters": dumped, "changed": sorted(changed),
                                           "diff": {name: dumped[name] for name in sorted(changed)}}))


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
