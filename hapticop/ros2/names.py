"""The names rmw_zenoh gives a ROS 2 graph on Zenoh: data keys, type hashes, liveliness tokens, QoS strings.

Followed from rmw_zenoh's design document and `liveliness_utils.cpp` (rmw_zenoh 0.2.x on Jazzy and the
Humble backport, 2025; docs/ros2.md pins what was checked):

- data key: `<domain>/<topic without its leading slash>/<pkg>::msg::dds_::<Type>_/<type hash>`, the hash
  REP-2016's `RIHS01_<sha256>` from Jazzy on and the literal `TypeHashNotSupported` on Humble; a key
  that differs in anything matches nothing, silently;
- liveliness token: `@ros2_lv/<domain>/<session zid>/<node id>/<entity id>/<NN|MP|MS>/<enclave>/<ns>/<node>`
  and, for a publisher or subscription, `/<topic>/<dds type>/<hash>/<qos>`, each name with `/` written
  `%` (so the root namespace and enclave `/` are `%`);
- QoS string: `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:
  <liveliness>,<lease s>,<ns>`, each field empty when it equals rmw_zenoh's default (reliable,
  volatile, keep last 42, the rest infinite/automatic), the kinds as rmw's enum numbers.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

Distro = Literal["jazzy", "humble"]
DISTROS: tuple[Distro, ...] = ("jazzy", "humble")
HUMBLE_HASH = "TypeHashNotSupported"
ADMIN_SPACE = "@ros2_lv"

# rmw's enum values (rmw/types.h) as rmw_zenoh writes them in a token
RELIABILITY = {"reliable": 1, "best_effort": 2}
DURABILITY = {"transient_local": 1, "volatile": 2}
HISTORY = {"keep_last": 1, "keep_all": 2}
DEFAULT_DEPTH = 42  # rmw_zenoh's depth for 0 ("system default"), and the one a token leaves out


@functools.cache
def typestore(distro: Distro):
    """rosbags' message definitions of that distribution (imported here only: a description needs none)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore({"jazzy": Stores.ROS2_JAZZY, "humble": Stores.ROS2_HUMBLE}[distro])


def dds_type(ros_type: str) -> str:
    """`geometry_msgs/msg/Twist` as DDS and rmw_zenoh name it: `geometry_msgs::msg::dds_::Twist_`."""
    package, kind, name = ros_type.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_hash(ros_type: str, distro: Distro) -> str:
    """REP-2016's hash of the type's definition in that distribution (Humble has none)."""
    if distro == "humble":
        return HUMBLE_HASH
    return typestore(distro).hash_rihs01(ros_type)


def data_key(domain: int, topic: str, ros_type: str, distro: Distro) -> str:
    return f"{domain}/{topic.strip('/')}/{dds_type(ros_type)}/{type_hash(ros_type, distro)}"


def mangle(name: str) -> str:
    """A name as one chunk of a key: its slashes as `%` (an empty name is not a chunk: `%` too)."""
    return name.replace("/", "%") or "%"


@dataclass(frozen=True)
class Qos:
    """The three policies a topic declares here; deadline, lifespan and liveliness are rmw_zenoh's defaults
    (it implements neither deadline nor lifespan)."""

    reliability: Literal["reliable", "best_effort"] = "reliable"
    durability: Literal["volatile", "transient_local"] = "volatile"
    history: Literal["keep_last", "keep_all"] = "keep_last"
    depth: int = 10

    def token(self) -> str:
        """The compact string of a liveliness token, with rmw_zenoh's defaults left empty."""
        reliability = "" if self.reliability == "reliable" else str(RELIABILITY[self.reliability])
        durability = "" if self.durability == "volatile" else str(DURABILITY[self.durability])
        history = "" if self.history == "keep_last" else str(HISTORY[self.history])
        depth = self.depth or DEFAULT_DEPTH
        return f"{reliability}:{durability}:{history},{'' if depth == DEFAULT_DEPTH else depth}:,:,:,,"

    @property
    def blocks(self) -> bool:
        """rmw_zenoh blocks a full queue only for keep-all and reliable; everything else drops."""
        return self.history == "keep_all" and self.reliability == "reliable"


@dataclass(frozen=True)
class Node:
    domain: int
    name: str
    namespace: str = "/"
    enclave: str = "/"

    def chunks(self, session: str, node_id: int, entity_id: int, kind: str) -> str:
        return (f"{ADMIN_SPACE}/{self.domain}/{session}/{node_id}/{entity_id}/{kind}/{mangle(self.enclave)}/"
                f"{mangle(self.namespace)}/{mangle(self.name)}")

    def token(self, session: str, node_id: int) -> str:
        """The node's own liveliness token (its entity id is its node id)."""
        return self.chunks(session, node_id, node_id, "NN")

    def endpoint_token(self, session: str, node_id: int, entity_id: int, publisher: bool, topic: str,
                       ros_type: str, distro: Distro, qos: Qos) -> str:
        """A publisher's (MP) or subscription's (MS) token: what `ros2 topic list` and `info` read."""
        return (f"{self.chunks(session, node_id, entity_id, 'MP' if publisher else 'MS')}/{mangle(topic)}/"
                f"{dds_type(ros_type)}/{type_hash(ros_type, distro)}/{qos.token()}")
