"""What a Foxglove user expects beside the raw streams: the scan, the robot's frames, the force arrow.

Recorder views (`observe.recorder.View`) that write Foxglove's well-known protobuf schemas,
encoded by the `foxglove-sdk` package (the optional `[foxglove]` extra), from the recorded
streams of the blocks that declare them (`Block.displays`: a kind, the block's ports that play
its roles, the figures only the block knows), whatever the streams are called:

- `laser_scan` -> `/scan` (`foxglove.LaserScan`, frame `laser`) from a scan's `ranges` and `angles`;
- `frames` -> `/tf` (`foxglove.FrameTransforms`) along REP-105's map -> odom -> base_link -> laser,
  from a robot's `pose` in the map (odom is where the robot started: simulated odometry is
  perfect, so map -> odom never moves) and the scanner's `mount` its `laser_scan` declares;
- `force_arrow` -> `/handle_force/arrow` (`foxglove.SceneUpdate`) a `force` as an arrow over
  the robot, in its axes (the Falcon's x right, y up, z towards the operator: hapticop.haptics.handle).

They run in the recorder, never on a real-time loop; frames and arrows are thinned to
`DISPLAY_PERIOD_NS`, which is all a display needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hapticop.composition.loader import Loaded
from hapticop.recording.mcapfile import RecordingFile, StreamInfo

DISPLAY_PERIOD_NS = 20_000_000  # 50 Hz of frames and arrows
FORCE_ARROW_M_PER_N = 0.05  # 10 N (the Falcon's most) is half a metre
ARROW_HEIGHT_M = 0.6  # over the robot's centre
SCAN_TOPIC, FRAMES_TOPIC, ARROW_TOPIC = "/scan", "/tf", "/handle_force/arrow"
MAP, ODOM, BASE, LASER = "map", "odom", "base_link", "laser"


def available() -> bool:
    """Whether the `[foxglove]` extra is installed."""
    try:
        import foxglove.messages  # noqa: F401
    except ImportError:
        return False
    return True


def _messages():
    import foxglove.messages

    return foxglove.messages


def _stamp(ns: int):
    return _messages().Timestamp(int(ns) // 1_000_000_000, int(ns) % 1_000_000_000)


def _yaw(theta: float):
    return _messages().Quaternion(x=0.0, y=0.0, z=math.sin(theta / 2), w=math.cos(theta / 2))


def _payload(stream: StreamInfo, sample) -> np.ndarray:
    """One drained sample's array (a view of the batch)."""
    return sample["payload"].view(np.dtype(stream.dtype)).reshape(stream.shape)


@dataclass
class _Channel:
    """A view's channel in the file, with its own sequence numbers."""

    topic: str
    kind: str  # the foxglove.messages class
    id: int = 0
    sequence: int = 0

    def open(self, file: RecordingFile, metadata: dict[str, str]) -> None:
        schema = getattr(_messages(), self.kind).get_schema()
        self.id = file.channel(self.topic, "protobuf", file.schema(schema.name, schema.encoding, schema.data), metadata)

    def write(self, file: RecordingFile, message, log_time_ns: int, publish_time_ns: int) -> None:
        self.sequence += 1
        file.write(self.id, log_time_ns, message.encode(), int(publish_time_ns), self.sequence)


@dataclass
class LaserScanView:
    """Each scan as a `foxglove.LaserScan` in the scanner's own frame (its beams turned back by its
    heading on the robot), once the beam angles are known."""

    ranges: str
    angles: str
    yaw_rad: float = 0.0
    streams: frozenset[str] = frozenset()
    channel: _Channel = field(default_factory=lambda: _Channel(SCAN_TOPIC, "LaserScan"))

    def __post_init__(self) -> None:
        self.streams = frozenset({self.ranges, self.angles})
        self.span: tuple[float, float] | None = None
        self.waiting: list[tuple[np.ndarray, int, int]] = []  # scans drained before the first angles

    def start(self, file: RecordingFile, streams: dict[str, StreamInfo]) -> None:
        self.file = file
        self.channel.open(file, {"from": f"{self.ranges}, {self.angles}", "frame": LASER})

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        for sample in samples:
            payload = _payload(stream, sample)
            if stream.name == self.angles:
                self.span = (float(payload[0]) - self.yaw_rad, float(payload[-1]) - self.yaw_rad)
                waiting, self.waiting = self.waiting, []
                for ranges, stamp, logged in waiting:
                    self._scan(ranges, stamp, logged)
            elif self.span is None:
                self.waiting.append((payload.copy(), int(sample["stamp_ns"]), log_time_ns))
            else:
                self._scan(payload, int(sample["stamp_ns"]), log_time_ns)

    def _scan(self, ranges: np.ndarray, stamp_ns: int, log_time_ns: int) -> None:
        start, end = self.span
        scan = _messages().LaserScan(timestamp=_stamp(stamp_ns), frame_id=LASER, start_angle=start, end_angle=end,
                                     ranges=ranges.astype(np.float64).tolist())
        self.channel.write(self.file, scan, log_time_ns, stamp_ns)

    def finish(self) -> None:
        self.waiting = []  # scans whose angles never came: nothing to place them with


@dataclass
class FramesView:
    """The REP-105 chain from the robot's pose in the map, with the scanner's mount."""

    pose: str
    mount: tuple[float, float, float]  # the scanner on the robot: x, y (m), heading (rad)
    streams: frozenset[str] = frozenset()
    channel: _Channel = field(default_factory=lambda: _Channel(FRAMES_TOPIC, "FrameTransforms"))

    def __post_init__(self) -> None:
        self.streams = frozenset({self.pose})
        self.odom: tuple[float, float, float] | None = None
        self.next_ns = 0

    def start(self, file: RecordingFile, streams: dict[str, StreamInfo]) -> None:
        self.file = file
        self.channel.open(file, {"from": self.pose, "frames": f"{MAP} -> {ODOM} -> {BASE} -> {LASER}"})

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        for sample in samples:
            stamp = int(sample["stamp_ns"])
            if stamp < self.next_ns:
                continue
            self.next_ns = stamp + DISPLAY_PERIOD_NS
            x, y, theta = (float(v) for v in _payload(stream, sample))
            if self.odom is None:
                self.odom = (x, y, theta)
            ox, oy, otheta = self.odom
            c, s = math.cos(otheta), math.sin(otheta)  # the pose relative to the start
            moved = (c * (x - ox) + s * (y - oy), -s * (x - ox) + c * (y - oy), theta - otheta)
            m = _messages()
            t = _stamp(stamp)
            links = [(MAP, ODOM, self.odom), (ODOM, BASE, moved), (BASE, LASER, self.mount)]
            frames = m.FrameTransforms(transforms=[
                m.FrameTransform(timestamp=t, parent_frame_id=parent, child_frame_id=child,
                                 translation=m.Vector3(x=px, y=py, z=0.0), rotation=_yaw(heading))
                for parent, child, (px, py, heading) in links])
            self.channel.write(self.file, frames, log_time_ns, stamp)

    def finish(self) -> None:
        pass


@dataclass
class ForceArrowView:
    """The force on the handle as an arrow over the robot, in the robot's axes."""

    force: str
    streams: frozenset[str] = frozenset()
    channel: _Channel = field(default_factory=lambda: _Channel(ARROW_TOPIC, "SceneUpdate"))

    def __post_init__(self) -> None:
        self.streams = frozenset({self.force})
        self.next_ns = 0

    def start(self, file: RecordingFile, streams: dict[str, StreamInfo]) -> None:
        self.file = file
        self.channel.open(file, {"from": self.force, "frame": BASE, "m_per_n": f"{FORCE_ARROW_M_PER_N:g}"})

    def samples(self, stream: StreamInfo, samples: np.ndarray, log_time_ns: int) -> None:
        for sample in samples:
            stamp = int(sample["stamp_ns"])
            if stamp < self.next_ns:
                continue
            self.next_ns = stamp + DISPLAY_PERIOD_NS
            f = _payload(stream, sample)
            self.channel.write(self.file, arrow(-float(f[2]), -float(f[0]), float(f[1]), stamp),
                               log_time_ns, stamp)

    def finish(self) -> None:
        pass


def arrow(fx: float, fy: float, fz: float, stamp_ns: int):
    """A force (N, robot axes) as a `foxglove.SceneUpdate` of one arrow from over the robot."""
    m = _messages()
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    # the rotation taking +x (an arrow's direction) onto the force: half-way vector between them
    if norm < 1e-9:
        q = m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    else:
        ux, uy, uz = fx / norm, fy / norm, fz / norm
        if ux < -1 + 1e-9:  # straight back: half a turn about z
            q = m.Quaternion(x=0.0, y=0.0, z=1.0, w=0.0)
        else:
            w = 1.0 + ux
            k = math.sqrt(w * w + uy * uy + uz * uz)
            q = m.Quaternion(x=0.0, y=-uz / k, z=uy / k, w=w / k)
    length = FORCE_ARROW_M_PER_N * norm
    shape = m.ArrowPrimitive(pose=m.Pose(position=m.Vector3(x=0.0, y=0.0, z=ARROW_HEIGHT_M), orientation=q),
                             shaft_length=0.75 * length, shaft_diameter=0.03, head_length=0.25 * length,
                             head_diameter=0.08, color=m.Color(r=1.0, g=0.3, b=0.1, a=1.0))
    entity = m.SceneEntity(timestamp=_stamp(stamp_ns), frame_id=BASE, id="handle_force", frame_locked=True,
                           arrows=[shape])
    return m.SceneUpdate(entities=[entity])


def views_for(loaded: Loaded, recorded: list[str]) -> list:
    """The views the blocks declare (`Block.displays`) whose ports' streams are all recorded or shown."""
    if not available():
        return []
    composition = loaded.composition
    by_port = {composition.streams[name].writer: name for name in reversed(recorded)}  # a port's first stream
    declared = []  # (kind, {role: stream}, options), in activity order
    for activity, resolved in loaded.activities.items():
        for display in resolved.block.displays(resolved.params):
            streams = {role: by_port.get(f"{activity}.{port}") for role, port in display.ports.items()}
            if all(streams.values()):
                declared.append((display.kind, streams, display.options))
    scans = [(streams, options) for kind, streams, options in declared if kind == "laser_scan"]
    mount = scans[-1][1].get("mount", (0.0, 0.0, 0.0)) if scans else (0.0, 0.0, 0.0)  # where `laser` sits
    views: list = []
    for kind, streams, options in declared:
        if kind == "laser_scan":
            views.append(LaserScanView(streams["ranges"], streams["angles"], float(options.get("yaw_rad", 0.0))))
    for kind, streams, _ in declared:
        if kind == "frames":
            views.append(FramesView(streams["pose"], tuple(mount)))
    for kind, streams, _ in declared:
        if kind == "force_arrow":
            views.append(ForceArrowView(streams["force"]))
    return views
