"""A ROS 2 topic and node as a composition describes them: the ROS 2 bridge's parameters and a stream's
`ros2:` option share these models (docs/ros2.md)."""

from __future__ import annotations

import re
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator
from pydantic_core import PydanticCustomError

from hapticop.composition.units import Duration, format_duration
from hapticop.ros2 import names
from hapticop.ros2.messages import LAYOUTS, Codec, ScanGeometry, describe, layout_of

RosType = Literal[tuple(sorted(LAYOUTS))]  # type: ignore[valid-type]
TOPIC = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$")  # ROS 2's fully qualified names


class Ros2Qos(BaseModel):
    """The QoS a topic declares (rmw_zenoh maps it: docs/ros2.md); deadline and lifespan are not implemented
    by rmw_zenoh and not offered here."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    reliability: Literal["reliable", "best_effort"] = Field("reliable", description="Zenoh's reliable or "
                                                            "best-effort channel")
    durability: Literal["volatile", "transient_local"] = Field(
        "volatile", description="transient_local: the last `depth` samples kept for late subscribers")
    history: Literal["keep_last", "keep_all"] = Field("keep_last", description="keep_all with reliable blocks a "
                                                      "full queue; every other combination drops")
    depth: int = Field(10, ge=0, le=10_000, description="samples kept (0: rmw_zenoh's default, 42)")

    def names(self) -> names.Qos:
        return names.Qos(self.reliability, self.durability, self.history, self.depth)


class ScanParams(BaseModel):
    """A published LaserScan's geometry (its ranges are the port)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    angle_min_rad: float = Field(-1.5707963267948966, description="the first beam's angle")
    angle_increment_rad: float = Field(0.017453292519943295, gt=0, description="between two beams")
    range_min_m: float = Field(0.05, ge=0, description="the shortest range measured")
    range_max_m: float = Field(10.0, gt=0, description="the longest range measured")


def _check_name_and_rate(topic: str, rate: int) -> None:
    """A topic's name and send period, as every published or subscribed topic must have them."""
    if not TOPIC.match(topic):
        raise PydanticCustomError("ros2_topic", "topic '{topic}' is not a ROS 2 name (letters, digits and "
                                  "'_' in chunks between '/')", {"topic": topic})
    if rate < 1_000_000:
        raise PydanticCustomError("ros2_rate", "rate {rate} is faster than 1kHz", {"rate": format_duration(rate)})


def _qualified(topic: str, namespace: str) -> str:
    """A relative topic under the node's namespace; an absolute one as it is."""
    return topic if topic.startswith("/") else f"{namespace.rstrip('/')}/{topic}"


class Ros2Topic(BaseModel):
    """One ROS 2 topic and the port that carries it."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    topic: str = Field(description="the topic's name, e.g. '/cmd_vel' (relative names are under the "
                       "node's namespace)")
    type: RosType = Field(description="its message type, e.g. 'geometry_msgs/msg/Twist'")
    shape: tuple[int, ...] | None = Field(None, description="the port's shape: a type admits a few "
                                          "(docs/ros2.md); default its first; [N] for a scan or joints")
    qos: Ros2Qos = Field(default_factory=Ros2Qos, description="reliability, durability, history and depth")
    rate: Duration = Field(20_000_000, description="published this often, as a rate or a period "
                           "('50Hz', '20ms'; at most 1kHz; publications only)")
    stale: Literal["zero", "skip"] = Field("zero", description="with no valid sample to publish: zeros (a "
                                           "stop, for a command) or nothing")
    max_age: Duration = Field(500_000_000, description="a sample older than this when it arrives is refused "
                              "('300ms'; subscriptions only)")
    frame_id: str = Field("", description="the header's frame")
    scan: ScanParams = Field(default_factory=ScanParams, description="a published LaserScan's geometry")
    joints: list[str] = Field(default_factory=list, description="a JointState's joint names")

    @model_validator(mode="after")
    def _fits(self) -> Ros2Topic:
        _check_name_and_rate(self.topic, self.rate)
        if self.shape is not None and layout_of(self.type, LAYOUTS[self.type][0].dtype, self.shape) is None:
            raise PydanticCustomError("ros2_shape", "shape {shape} does not fit {type}: it takes {fits}",
                                      {"shape": list(self.shape), "type": self.type, "fits": describe(self.type)})
        if self.shape is None and LAYOUTS[self.type][0].size is None:
            raise PydanticCustomError("ros2_shape", "{type} needs 'shape: [N]' (its length), or a port to take it "
                                      "from", {"type": self.type})
        return self

    @property
    def port_shape(self) -> tuple[int, ...]:
        if self.shape is not None:
            return self.shape
        size = LAYOUTS[self.type][0].size
        return () if size == 0 else (size,)

    def codec(self, distro: names.Distro) -> Codec:
        s = self.scan
        return Codec(self.type, distro, LAYOUTS[self.type][0].dtype, self.port_shape, self.frame_id,
                     ScanGeometry(s.angle_min_rad, s.angle_increment_rad, s.range_min_m, s.range_max_m),
                     tuple(self.joints))

    def fully_qualified(self, namespace: str) -> str:
        return _qualified(self.topic, namespace)


class Ros2Flags(BaseModel):
    """The run's flags as a `std_msgs/msg/String` topic: a JSON object of every flag by its full name."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    topic: str = Field("/hapticop/flags", description="the topic's name")
    rate: Duration = Field(100_000_000, description="sent this often, and at once when a flag changes ('10Hz')")
    qos: Ros2Qos = Field(default_factory=Ros2Qos, description="reliability, durability, history and depth")

    @model_validator(mode="after")
    def _fits(self) -> Ros2Flags:
        _check_name_and_rate(self.topic, self.rate)
        return self

    def fully_qualified(self, namespace: str) -> str:
        return _qualified(self.topic, namespace)


class Ros2Node(BaseModel):
    """The ROS 2 node hapticop is on the ROS graph: its domain, name, distribution and Zenoh endpoints."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    domain: int = Field(0, ge=0, le=232, description="the ROS domain id (ROS_DOMAIN_ID)")
    node: str = Field("hapticop", pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", description="the node's name")
    namespace: str = Field("/", pattern=r"^/([A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?$",
                           description="the node's namespace")
    distro: names.Distro = Field("jazzy", description="the ROS 2 distribution: its type hashes are in every key "
                                 "(Humble has none), and a mismatch matches nothing")
    mode: Literal["peer", "client"] = Field("peer", description="'peer': listen and connect directly; 'client': "
                                            "through the Zenoh routers in 'connect' (rmw_zenohd)")
    listen: list[str] = Field(default_factory=list, description="this node's Zenoh endpoints (peer mode)")
    connect: list[str] = Field(default_factory=list, description="the endpoints of the peers or routers")
    flags: Ros2Flags | None = Field(None, description="the run's flags published as a std_msgs/msg/String topic "
                                    "(JSON: every flag by its full name), e.g. '{topic: /hapticop/flags}'")

    @model_validator(mode="after")
    def _endpoints(self) -> Ros2Node:
        if self.mode == "client" and (self.listen or not self.connect):
            raise PydanticCustomError("ros2_client", "mode 'client' connects to routers: it needs 'connect' and "
                                      "no 'listen'")
        if self.mode == "peer" and not (self.listen or self.connect):
            raise PydanticCustomError("ros2_peer", "mode 'peer' needs 'listen' or 'connect' endpoints "
                                      "(there is no scouting)")
        return self
