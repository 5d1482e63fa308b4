"""Each network bridge's link figures as a `/link/BRIDGE` JSON channel, from what it tells `status`.

A bridge (docs/teleop.md) tells its run directory its round trip, jitter, loss, clock offset and
whether the link is up, lost or degraded once a second, for `hapticop status`. The recorder reads
those same facts and writes each new one as a message, so a recording shows what the link did
next to what the loops did, without a stream (or a reader) for each figure. Plain JSON with a JSON
Schema, like the loops' timing: Foxglove plots `/link/bridge.rtt_ms`.
"""

from __future__ import annotations

import json
from pathlib import Path

from hapticop import published
from hapticop.recording.mcapfile import LINK_TOPIC
from hapticop.recording.outputs import Output

LINKS = "network"  # the kind of fact a bridge publishes (hapticop.blocks.bridge)
READ_NS = 500_000_000  # twice per publication: a figure is recorded within half a second of being told
_NUMBER = {"type": ["number", "null"]}
SCHEMA = {
    "title": "hapticop.LinkFigures", "type": "object",
    "description": "a network bridge's link to the other hosts (what `hapticop status` prints)",
    "properties": {
        "peers": {"type": "array", "items": {"type": "string"}},
        "up": {"type": "boolean"}, "lost": {"type": "boolean"}, "degraded": {"type": "boolean"},
        "rtt_ms": {**_NUMBER, "description": "round trip, the median of the last pings"},
        "jitter_ms": {**_NUMBER, "description": "smoothed change of the round trip between pings"},
        "loss": {**_NUMBER, "description": "fraction of the last pings unanswered"},
        "offset_ms": {**_NUMBER, "description": "the other host's clock minus this one's"},
        "offset_error_ms": {**_NUMBER, "description": "bound on the offset's error"},
    },
}


class LinkChannel:
    """A recorder source: every bridge's newest figures, one message each time they change."""

    def __init__(self, run_dir: Path):
        self.run_dir = Path(run_dir)
        self.out: Output | None = None
        self.channels: dict[str, int] = {}
        self.last: dict[str, dict] = {}
        self.read_ns = 0
        self.sequence = 0

    def start(self, out: Output) -> None:
        self.out = out
        self.schema = out.schema("hapticop.LinkFigures", "jsonschema", json.dumps(SCHEMA).encode())

    def poll(self, now_ns: int) -> None:
        if self.out is None or now_ns < self.read_ns:
            return
        self.read_ns = now_ns + READ_NS
        folder = self.run_dir / LINKS
        if not folder.is_dir():
            return
        for path in sorted(folder.glob("*.pickle")):
            bridge = path.stem
            figures = published.published(self.run_dir, LINKS, bridge)
            if not isinstance(figures, dict) or figures == self.last.get(bridge):
                continue
            self.last[bridge] = figures
            if bridge not in self.channels:
                self.channels[bridge] = self.out.channel(LINK_TOPIC.format(bridge), "json", self.schema,
                                                         {"bridge": bridge})
            self.sequence += 1
            self.out.write(self.channels[bridge], now_ns, json.dumps(figures).encode(), now_ns, self.sequence)

    def finish(self, now_ns: int) -> None:
        self.read_ns = 0
        self.poll(now_ns)  # what was told since the last pass
