"""The ROS 2 streams of a recording as rosbag2 writes them: a channel per topic, `cdr` messages, `ros2msg`.

A recorder view (`observe.recorder.View`): each recorded stream declared with `ros2:` gets, beside its
own raw channel, a channel named by its ROS 2 topic whose schema is the message's definition as rosbag2
writes it (rosbags' type store, the type and its dependencies in `.msg` text) and whose messages are the
samples in CDR, encoded by the same codec the ROS 2 node uses. A published topic is thinned to its
declared rate, as the node sends it. It runs in the recorder process, never on a real-time loop.

The run's file cannot itself be a rosbag2 bag: its raw channels are protobuf, which rosbag2's readers
refuse in a file of profile `ros2`. So the same messages also go to a bag of their own beside it, as
rosbag2's MCAP storage writes one: a directory `<run>_ros2/` holding `<run>_ros2_0.mcap` (profile
`ros2`, the ROS 2 channels only, each with its `offered_qos_profiles` and `topic_type_hash`, and the
`rosbag2` metadata record) and `metadata.yaml`, written last, when the run ends (docs/ros2.md).
"""

from __future__ import annotations

import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from ruamel.yaml import YAML

from hapticop.composition.description import Composition
from hapticop.recording.mcapfile import RecordingFile, StreamInfo
from hapticop.ros2 import names
from hapticop.ros2.topics import Ros2Topic

BAG_VERSION = {"jazzy": 8, "humble": 5}  # what each distribution's rosbag2 writes (and reads at most)
INFINITE = {"sec": 9223372036, "nsec": 854775807}  # rmw's infinite duration, as rosbag2 writes it


def bag_of(recording: Path) -> Path:
    """The rosbag2 bag directory beside a recording: `run.mcap` -> `run_ros2/`."""
    return recording.with_name(f"{recording.stem}_ros2")


def _yaml(value) -> str:
    yaml = YAML(typ="safe")
    yaml.default_flow_style = False
    out = io.StringIO()
    yaml.dump(value, out)
    return out.getvalue()


def qos_profiles(option: Ros2Topic) -> str:
    """The topic's QoS as rosbag2 (version 8) serialises `offered_qos_profiles`: a YAML list, rmw's enums."""
    q = option.qos
    return _yaml([{
        "history": names.HISTORY[q.history], "depth": q.depth or names.DEFAULT_DEPTH,
        "reliability": names.RELIABILITY[q.reliability], "durability": names.DURABILITY[q.durability],
        "deadline": INFINITE, "lifespan": INFINITE, "liveliness": 1, "liveliness_lease_duration": INFINITE,
        "avoid_ros_namespace_conventions": False}]).strip()


@dataclass
class Ros2Channels:
    """Channels `ros2msg`/`cdr` for the recorded streams with `ros2:` (by stream: its topic's full name, its
    option, and the period in ns it is thinned to, 0 for a subscription: every sample that arrived), in the
    run's file and in the bag beside `path` (none: the run's file only)."""

    topics: dict[str, tuple[str, Ros2Topic, int]]
    distro: names.Distro = "jazzy"
    path: Path | None = None
    streams: frozenset[str] = frozenset()
    ids: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.streams = frozenset(self.topics)
        self.next_ns = dict.fromkeys(self.topics, 0)
        self.sequence = dict.fromkeys(self.topics, 0)

    def start(self, file, streams: dict[str, StreamInfo]) -> None:
        self.file, store = file, names.typestore(self.distro)
        self.bag = self.bag_ids = None
        if self.path is not None:
            directory = bag_of(self.path)
            directory.mkdir(parents=True, exist_ok=True)
            self.bag = RecordingFile(directory / f"{directory.name}_0.mcap", profile="ros2")
            self.bag_ids = {}
        self.codecs = {}
        for name, (topic, option, _) in self.topics.items():
            self.codecs[name] = option.codec(self.distro)  # the node's own: frame, scan geometry, joint names
            text, _ = store.generate_msgdef(option.type, ros_version=2)
            metadata = {"offered_qos_profiles": qos_profiles(option)}
            if self.distro != "humble":
                metadata["topic_type_hash"] = names.type_hash(option.type, self.distro)
            schema = file.schema(option.type, "ros2msg", text.encode())
            self.ids[name] = file.channel(topic, "cdr", schema, {**metadata, "from_stream": name})  # not a raw one
            if self.bag is not None:
                schema = self.bag.schema(option.type, "ros2msg", text.encode())
                self.bag_ids[name] = self.bag.channel(topic, "cdr", schema, metadata)

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        period_ns = self.topics[stream.name][2]
        values = samples["payload"].view(np.dtype(stream.dtype)).reshape((len(samples), *stream.shape))
        for sample, value in zip(samples, values, strict=True):
            stamp = int(sample["stamp_ns"])
            if stamp < self.next_ns[stream.name]:
                continue
            self.next_ns[stream.name] = stamp + period_ns
            self.sequence[stream.name] += 1
            data = self.codecs[stream.name].encode(value, stamp)
            self.file.write(self.ids[stream.name], log_time_ns, data, stamp, self.sequence[stream.name])
            if self.bag is not None:  # rosbag2's time of a message is its log time: here, the sample's own
                self.bag.write(self.bag_ids[stream.name], stamp, data, stamp, self.sequence[stream.name])

    def finish(self) -> None:
        if self.bag is None:
            return
        info = self.metadata()
        self.bag.metadata("rosbag2", {"serialized_metadata": _yaml(info).strip()})  # as rosbag2's MCAP storage
        path = self.bag.finish()
        text = _yaml({"rosbag2_bagfile_information": info})
        (path.parent / "metadata.yaml.part").write_text(text)
        (path.parent / "metadata.yaml.part").replace(path.parent / "metadata.yaml")  # last: the bag is whole

    def metadata(self) -> dict:
        """rosbag2's `rosbag2_bagfile_information`, in the version this distribution's rosbag2 writes."""
        bag, version = self.bag, BAG_VERSION[self.distro]
        start = bag.first_ns or 0
        duration, count = max(0, bag.last_ns - start), bag.messages
        topics = []
        for name, (topic, option, _) in self.topics.items():
            meta = {"name": topic, "type": option.type, "serialization_format": "cdr",
                    "offered_qos_profiles": qos_profiles(option)}
            if version >= 7:
                meta["type_description_hash"] = names.type_hash(option.type, self.distro)
            topics.append({"topic_metadata": meta, "message_count": bag.counts[self.bag_ids[name]]})
        info = {"version": version, "storage_identifier": "mcap", "relative_file_paths": [bag.path.name],
                "duration": {"nanoseconds": duration}, "starting_time": {"nanoseconds_since_epoch": start},
                "message_count": count, "topics_with_message_count": topics,
                "compression_format": "", "compression_mode": "",
                "files": [{"path": bag.path.name, "starting_time": {"nanoseconds_since_epoch": start},
                           "duration": {"nanoseconds": duration}, "message_count": count}]}
        if version >= 8:
            info.update(custom_data=None, ros_distro=self.distro)
        return info


def ros2_channels(composition: Composition, recorded: list[str], path: Path | None = None) -> list[Ros2Channels]:
    """The view of the recorded streams declared with `ros2:` (none: no view), with its bag beside `path`."""
    topics = {}
    for name in recorded:
        option = composition.streams[name].ros2 if name in composition.streams else None
        if option is not None:
            published = composition.streams[name].writer.split(".", 1)[0] != "ros2"
            namespace = composition.ros2.namespace if composition.ros2 else "/"
            topics[name] = (option.fully_qualified(namespace), option, option.rate if published else 0)
    if not topics:
        return []
    return [Ros2Channels(topics, composition.ros2.distro if composition.ros2 else "jazzy",
                         Path(path) if path is not None else None)]
