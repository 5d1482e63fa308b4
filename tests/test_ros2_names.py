"""rmw_zenoh's names and bytes for hapticop's ROS 2 streams, against pinned values and an independent client."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from hapticop.ros2 import attachment, names
from hapticop.ros2.messages import LAYOUTS, Codec, ScanGeometry, layout_of

FIXTURES = Path(__file__).parent / "fixtures" / "ros2"
GOLDEN = json.loads((FIXTURES / "golden.json").read_text())
MSGS = {k: v for k, v in json.loads((FIXTURES / "msgs.json").read_text()).items() if not k.startswith("_")}


def test_type_hashes_pinned_and_recomputed_by_an_independent_client():
    from zenoh_ros2_sdk.utils import get_type_hash

    for ros_type, expected in GOLDEN["hashes"].items():
        assert names.type_hash(ros_type, "jazzy") == expected
        assert names.type_hash(ros_type, "humble") == "TypeHashNotSupported"
        # zenoh-ros2-sdk computes REP-2016's hash with code of its own, from the .msg texts
        assert get_type_hash(ros_type, msg_definition=MSGS[ros_type], dependencies=MSGS) == expected


def test_data_keys():
    for case in GOLDEN["keys"]:
        assert names.data_key(case["domain"], case["topic"], case["type"], case["distro"]) == case["key"]


def test_attachment_bytes():
    from zenoh_ros2_sdk.attachment import Attachment

    case = GOLDEN["attachment"]
    data = attachment.pack(case["sequence"], case["stamp_ns"], bytes.fromhex(case["gid"]))
    assert data.hex() == case["bytes"] and len(data) == 33
    assert attachment.unpack(data) == (case["sequence"], case["stamp_ns"], bytes.fromhex(case["gid"]))
    theirs = Attachment.from_bytes(data)
    assert (theirs.sequence_id, theirs.timestamp_ns, theirs.gid.hex()) == (1, case["stamp_ns"], case["gid"])
    assert attachment.unpack(data[:-1]) is None  # a 2024 build's map, or anything else, is not ours
    assert attachment.unpack(data[:16] + b"\x0f" + data[17:]) is None


def test_liveliness_tokens_and_qos():
    from zenoh_ros2_sdk.entity import EndpointEntity, EntityKind, NodeEntity
    from zenoh_ros2_sdk.keyexpr import endpoint_liveliness_keyexpr, node_liveliness_keyexpr

    t = GOLDEN["tokens"]
    node = names.Node(0, "hapticop")
    assert node.token(t["session"], 0) == t["node"]
    twist, scan = "geometry_msgs/msg/Twist", "sensor_msgs/msg/LaserScan"
    assert node.endpoint_token(t["session"], 0, 1, True, "/cmd_vel", twist, "jazzy",
                               names.Qos("best_effort", depth=1)) == t["publisher"]
    assert node.endpoint_token(t["session"], 0, 2, False, "/scan", scan, "jazzy", names.Qos()) == t["subscription"]
    # the independent client writes the same strings
    theirs = NodeEntity(domain_id=0, session_id=t["session"], node_id=0, node_name="hapticop")
    assert node_liveliness_keyexpr(theirs) == t["node"]
    assert endpoint_liveliness_keyexpr(EndpointEntity(
        node=theirs, entity_id=2, kind=EntityKind.SUBSCRIPTION, name="/scan", dds_type_name=names.dds_type(scan),
        type_hash=names.type_hash(scan, "jazzy"), qos="::,10:,:,:,,")) == t["subscription"]
    for case in GOLDEN["qos"]:
        assert names.Qos(**case["qos"]).token() == case["token"]
    assert names.Qos("reliable", history="keep_all").blocks and not names.Qos("reliable").blocks


def test_twist_cdr_pinned():
    case = GOLDEN["cdr"]
    codec = Codec(case["type"], "jazzy", "float64", (3,))
    data = codec.encode(np.array(case["value"]), 0)
    assert data.hex() == case["bytes"]
    out = np.zeros(3)
    assert codec.decode(data, out) is None and out.tolist() == case["value"]


VALUES = {3: [0.5, -0.25, 0.75], 6: [0.5, -0.25, 0.125, 0.0, 0.1, 0.75], 7: [1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0]}


@pytest.mark.parametrize("distro", names.DISTROS)
@pytest.mark.parametrize("ros_type", sorted(LAYOUTS))
def test_every_layout_round_trips(ros_type, distro):
    for layout in LAYOUTS[ros_type]:
        shape = () if layout.size == 0 else (layout.size or 5,)
        value = (np.array(1700000000.25) if layout.size == 0 else
                 np.arange(1, 6, dtype=layout.dtype) / 4 if layout.size is None else np.array(VALUES[layout.size]))
        if ros_type == "nav_msgs/msg/Odometry":
            value[2] = 0.75  # a yaw
        codec = Codec(ros_type, distro, layout.dtype, shape, frame_id="base_link",
                      scan=ScanGeometry(angle_min_rad=-0.5, angle_increment_rad=0.25))
        out, angles = np.zeros(shape, layout.dtype), np.zeros(shape, np.float32)
        assert codec.decode(codec.encode(value, 1_700_000_000_250_000_000), out, angles) is None
        np.testing.assert_allclose(out, value, rtol=1e-12, atol=1e-12)
        if ros_type == "sensor_msgs/msg/LaserScan":
            np.testing.assert_allclose(angles, -0.5 + 0.25 * np.arange(5))


def test_decoding_refuses_what_does_not_fit():
    twist = Codec("geometry_msgs/msg/Twist", "jazzy", "float64", (3,))
    out = np.full(3, 7.0)
    good = twist.encode(np.array([1.0, 0.0, 0.5]), 0)
    assert twist.decode(good[:-4], out) == "malformed CDR"
    assert twist.decode(b"", out) == "malformed CDR"
    assert twist.decode(twist.encode(np.array([math.nan, 0.0, 0.0]), 0), out) == "not finite"
    assert twist.decode(twist.encode(np.array([math.inf, 0.0, 0.0]), 0), out) == "not finite"
    assert out.tolist() == [7.0, 7.0, 7.0]  # nothing half-written
    scan = Codec("sensor_msgs/msg/LaserScan", "jazzy", "float32", (4,))
    ranges = np.zeros(4, np.float32)
    assert scan.decode(Codec("sensor_msgs/msg/LaserScan", "jazzy", "float32", (5,)).encode(
        np.ones(5, np.float32), 0), ranges) == "5 ranges, not 4"
    assert scan.decode(scan.encode(np.array([1, math.inf, 2, 3], np.float32), 0), ranges) is None  # no return
    assert scan.decode(scan.encode(np.array([1, math.nan, 2, 3], np.float32), 0), ranges) == "not finite"


def test_layouts_say_what_fits():
    assert layout_of("geometry_msgs/msg/Twist", "float64", (3,)).unit == "m/s, m/s, rad/s"
    assert layout_of("geometry_msgs/msg/Twist", "float64", (4,)) is None
    assert layout_of("geometry_msgs/msg/Twist", "float32", (3,)) is None
    assert layout_of("sensor_msgs/msg/LaserScan", "float32", (811,)).unit == "m"
    assert layout_of("sensor_msgs/msg/LaserScan", "float64", (811,)) is None
    with pytest.raises(ValueError, match="does not fit geometry_msgs/msg/Twist"):
        Codec("geometry_msgs/msg/Twist", "jazzy", "float64", (2,))
