"""The ROS 2 streams of a recording as rosbag2 writes them: a channel per topic, `cdr` messages, `ros2msg`.

A recorder view (`observe.recorder.View`): each recorded stream declared with `ros2:` gets, beside its
own raw channel, a channel named by its ROS 2 topic whose schema is the message's definition as rosbag2
writes it (rosbags' type store, the type and its dependencies in `.msg` text) and whose messages are the
samples in CDR, encoded by the same codec the ROS 2 node uses. A published topic is thinned to its
declared rate, as the node sends it. It runs in the recorder process, never on a real-time loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hapticop.composition.description import Composition
from hapticop.recording.mcapfile import RecordingFile, StreamInfo
from hapticop.ros2.names import typestore
from hapticop.ros2.topics import Ros2Topic


@dataclass
class Ros2Channels:
    """Channels `ros2msg`/`cdr` for the recorded streams with `ros2:` (by stream: its topic's full name, its
    option, and the rate it is thinned to, 0 for a subscription: every sample that arrived)."""

    topics: dict[str, tuple[str, Ros2Topic, float]]
    distro: str = "jazzy"
    streams: frozenset[str] = frozenset()
    ids: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.streams = frozenset(self.topics)
        self.next_ns = dict.fromkeys(self.topics, 0)
        self.sequence = dict.fromkeys(self.topics, 0)

    def start(self, file: RecordingFile, streams: dict[str, StreamInfo]) -> None:
        self.file, store = file, typestore(self.distro)
        self.codecs = {}
        for name, (topic, option, _) in self.topics.items():
            self.codecs[name] = option.codec(self.distro)  # the node's own: frame, scan geometry, joint names
            text, _ = store.generate_msgdef(option.type, ros_version=2)
            schema = file.schema(option.type, "ros2msg", text.encode())
            self.ids[name] = file.channel(topic, "cdr", schema, {"from_stream": name})  # not a raw stream's

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        period_ns = int(1e9 / self.topics[stream.name][2]) if self.topics[stream.name][2] else 0
        values = samples["payload"].view(np.dtype(stream.dtype)).reshape((len(samples), *stream.shape))
        for sample, value in zip(samples, values, strict=True):
            stamp = int(sample["stamp_ns"])
            if stamp < self.next_ns[stream.name]:
                continue
            self.next_ns[stream.name] = stamp + period_ns
            self.sequence[stream.name] += 1
            data = self.codecs[stream.name].encode(value, stamp)
            self.file.write(self.ids[stream.name], log_time_ns, data, stamp, self.sequence[stream.name])

    def finish(self) -> None:
        pass


def ros2_channels(composition: Composition, recorded: list[str]) -> list[Ros2Channels]:
    """The view of the recorded streams declared with `ros2:` (none: no view)."""
    topics = {}
    for name in recorded:
        option = composition.streams[name].ros2 if name in composition.streams else None
        if option is not None:
            published = composition.streams[name].writer.split(".", 1)[0] != "ros2"
            namespace = composition.ros2.namespace if composition.ros2 else "/"
            topics[name] = (option.fully_qualified(namespace), option, option.rate_hz if published else 0.0)
    if not topics:
        return []
    return [Ros2Channels(topics, composition.ros2.distro if composition.ros2 else "jazzy")]
