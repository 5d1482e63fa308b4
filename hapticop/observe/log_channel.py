"""The run's log records as Foxglove's `foxglove.Log` channel, read from the files its writers append.

Every process of a run appends its threads' and activities' records to one file per owner in
the run directory (`logs.LogWriter`), off the real-time path. The recorder follows those files
as they grow, so it needs no queue of its own into any loop, and a child process's records
come the same way as the main process's. Needs the `[foxglove]` extra (the message's encoding),
like the other Foxglove channels.
"""

from __future__ import annotations

from pathlib import Path

from hapticop.recording import scene
from hapticop.recording.mcapfile import LOG_TOPIC
from hapticop.recording.outputs import Output
from hapticop.runtime.logs import Level, parse_line

RESCAN_NS = 1_000_000_000  # new owners' files are looked for once a second
READ_NS = 200_000_000  # the files are read five times a second
_FOXGLOVE_LEVEL = {Level.ALWAYS: "Info", Level.ERROR: "Error", Level.WARNING: "Warning", Level.INFO: "Info",
                   Level.DEBUG: "Debug"}  # foxglove.messages.LogLevel's names


class LogChannel:
    """A recorder source: each new line of the run's log files, one `foxglove.Log` message."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self.files: dict[Path, tuple] = {}  # path -> (handle, the unfinished last line)
        self.rescan_ns = 0
        self.out: Output | None = None
        self.sequence = 0
        self.now_ns = 0
        self.read_ns = 0
        self.last_ns, self.last_level = 0, Level.INFO  # a continuation line's, taken from the line before it

    def start(self, out: Output) -> None:
        if not scene.available():
            return
        import foxglove.messages

        self.messages = foxglove.messages
        schema = foxglove.messages.Log.get_schema()
        self.out = out
        self.channel = out.channel(LOG_TOPIC, "protobuf", out.schema(schema.name, schema.encoding, schema.data),
                                   {"from": str(self.run_dir / "*.log")})

    def poll(self, now_ns: int) -> None:
        if self.out is None or now_ns < self.read_ns:
            return
        self.now_ns, self.read_ns = now_ns, now_ns + READ_NS
        if now_ns >= self.rescan_ns:
            self.rescan_ns = now_ns + RESCAN_NS
            for path in sorted(self.run_dir.glob("*.log")):
                if path not in self.files:
                    self.files[path] = (open(path, "rb"), b"")  # noqa: SIM115 - closed by finish()
        for path, (handle, rest) in self.files.items():
            data = handle.read()
            if not data:
                continue
            lines = (rest + data).split(b"\n")
            self.files[path] = (handle, lines.pop())
            for line in lines:
                self._record(path.stem, line.decode("utf-8", "replace"), now_ns)

    def _record(self, owner: str, line: str, now_ns: int) -> None:
        parsed = parse_line(line)
        stamp, level, text = parsed if parsed is not None else (self.last_ns, self.last_level, line)
        self.last_ns, self.last_level = stamp, level
        m = self.messages
        message = m.Log(timestamp=m.Timestamp(stamp // 1_000_000_000, stamp % 1_000_000_000),
                        level=getattr(m.LogLevel, _FOXGLOVE_LEVEL[level]), message=text, name=owner)
        self.sequence += 1
        self.out.write(self.channel, now_ns, message.encode(), stamp, self.sequence)

    def finish(self, now_ns: int) -> None:
        self.rescan_ns = self.read_ns = 0
        self.poll(now_ns)  # the lines written since the last pass
        for handle, _ in self.files.values():
            handle.close()
        self.files = {}
