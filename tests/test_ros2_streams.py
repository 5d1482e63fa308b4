"""Streams with `ros2:`: the loader's rewrite to a generated ROS 2 node, the checks of a port against its
message (located), and the option end to end against the independent ROS 2 client (tests/ros2_client.py)."""

from __future__ import annotations

from ruamel.yaml import YAML

from hapticop.composition.loader import declared_port
from hapticop.composition.ros2streams import expand
from hapticop.validation import validate_text
from tests.test_ros2_bridge import _echo_through, _free_port

SYSTEM = """\
version: 1
name: handle_to_ros
ros2: {node: operator, domain: 3, connect: [tcp/127.0.0.1:7447]}
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, falcon_sim, spring]}}
activities:
  mediator: {block: mediator}
  falcon_sim: {block: falcon_simulator}
  spring: {block: spring_damper}
streams:
  position: {from: falcon_sim.handle_position, to: [spring.position]}
  force: {from: spring.force, to: [falcon_sim.hand_force]}
  handle_pose:
    from: falcon_sim.handle_position
    ros2: {topic: /handle/pose, type: geometry_msgs/msg/PoseStamped, frame_id: falcon, rate: 100Hz}
  handle_force:
    from: spring.force
    ros2: {topic: /handle/wrench, type: geometry_msgs/msg/WrenchStamped}
  goal:
    max_age: 300ms
    ros2: {topic: /goal, type: geometry_msgs/msg/PoseStamped, qos: {reliability: best_effort, depth: 1}}
"""

EXPANDED = {
    "threads": {"ros2": {"period": "5000000ns", "deploy": "process", "schedules": {0: ["ros2"]},
                         "doc": "normal scheduling, its own process: Zenoh never shares a GIL with a real-time "
                                "loop"}},
    "activities": {"ros2": {
        "block": "ros2_bridge", "doc": "the streams with 'ros2:', as the ROS 2 node this system is (generated)",
        "params": {"domain": 3, "node": "operator", "connect": ["tcp/127.0.0.1:7447"],
                   "publish": {
                       "handle_pose": {"topic": "/handle/pose", "type": "geometry_msgs/msg/PoseStamped",
                                       "shape": [3], "rate": "10ms", "frame_id": "falcon"},  # shapes: the ports'
                       "handle_force": {"topic": "/handle/wrench", "type": "geometry_msgs/msg/WrenchStamped",
                                        "shape": [3]}},
                   "subscribe": {
                       "goal": {"topic": "/goal", "type": "geometry_msgs/msg/PoseStamped",
                                "qos": {"reliability": "best_effort", "depth": 1}}}}}},
    "streams": {"handle_pose": {"to": ["ros2.handle_pose"]}, "handle_force": {"to": ["ros2.handle_force"]},
                "goal": {"from": "ros2.goal"}},
}


def _plain(node):
    if isinstance(node, dict):
        return {k: _plain(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_plain(v) for v in node]
    return node


def test_the_loader_writes_the_ros2_node_for_the_streams_that_declare_a_topic():
    tree = YAML(typ="rt").load(SYSTEM)
    expanded, found = expand(tree, declared_port)
    assert found == []
    out = _plain(expanded)
    assert out["threads"]["ros2"] == EXPANDED["threads"]["ros2"]
    assert out["activities"]["ros2"] == EXPANDED["activities"]["ros2"]
    for name, sides in EXPANDED["streams"].items():
        for key, value in sides.items():
            assert out["streams"][name][key] == value, name
    assert "ros2" not in _plain(tree)["activities"]  # the file's own tree is left as written
    validated = validate_text(SYSTEM)
    assert validated.report.ok, [d.to_text() for d in validated.report.diagnostics]


def _findings(text: str) -> list[str]:
    validated = validate_text(text, file="sys.yaml")
    return [f"{d.line} {'.'.join(map(str, d.path))} {d.rule}: {d.message}" for d in validated.report.diagnostics]


def test_a_port_that_does_not_fit_its_message_is_located_at_the_option():
    bad = SYSTEM.replace("geometry_msgs/msg/PoseStamped, frame_id", "geometry_msgs/msg/Twist, frame_id")
    found = _findings(bad)
    assert len(found) == 1 and found[0].startswith("15 streams.handle_pose.ros2.type ros2-unit:"), found
    assert "carries [m/s, m/s, rad/s]" in found[0]
    bad = SYSTEM.replace("type: geometry_msgs/msg/WrenchStamped}", "type: geometry_msgs/msg/WrenchStamped, "
                         "shape: [6]}")
    found = _findings(bad)
    assert len(found) == 1 and found[0].startswith("18 streams.handle_force.ros2.shape ros2-message:"), found
    bad = SYSTEM.replace("type: geometry_msgs/msg/WrenchStamped}", "type: sensor_msgs/msg/LaserScan, shape: [3]}")
    found = _findings(bad)
    assert len(found) == 1 and found[0].startswith("18 streams.handle_force.ros2.type ros2-message:"), found
    assert "does not fit sensor_msgs/msg/LaserScan" in found[0]


def test_a_bad_option_or_node_is_a_located_finding_not_a_rewrite():
    found = _findings(SYSTEM.replace("topic: /goal", "topic: /2goal"))
    assert any(f.startswith("21 streams.goal.ros2") and "not a ROS 2 name" in f for f in found), found
    found = _findings(SYSTEM.replace("frame_id: falcon,", "frame_id: falcon, distro: humble,"))
    assert found == ["15 streams.handle_pose.ros2.distro ros2-distro: distro 'humble' is not the node's 'jazzy'"]
    writer = "    from: falcon_sim.handle_position\n"
    found = _findings(SYSTEM.replace(writer, writer + "    to: [x.y]\n"))
    assert any(f.startswith("16 streams.handle_pose.ros2 ros2-sides") for f in found), found
    found = _findings(SYSTEM.replace("connect: [tcp/127.0.0.1:7447]", "mode: client"))
    assert any(f.startswith("3 ros2") and "needs 'connect'" in f for f in found), found
    found = _findings(SYSTEM.replace("ros2: {node: operator, domain: 3, connect: [tcp/127.0.0.1:7447]}\n", ""))
    assert any(f.startswith("14 streams.handle_pose.ros2 ros2-node") for f in found), found


OPTION = """
version: 1
name: ros2_echo
ros2: {node: hapticop, MODE}
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, echo]}}
activities:
  mediator: {block: mediator}
  echo: {block: echo, params: {dtype: float64, shape: [3], unit: "m/s, m/s, rad/s"}}
streams:
  cmd_in:
    to: [echo.input]
    max_age: 200ms
    ros2: {topic: /cmd_in, type: geometry_msgs/msg/Twist, qos: {reliability: best_effort, depth: 1}}
  cmd_out:
    from: echo.output
    max_age: 200ms
    ros2: {topic: /cmd_out, type: geometry_msgs/msg/Twist, rate: 50Hz}
"""


def test_the_independent_client_sees_and_decodes_streams_declared_with_the_option(tmp_path):
    """The client lists the generated node and both topics, and its twist comes back through hapticop."""
    port = _free_port()
    _echo_through(tmp_path, port, f"listen: [tcp/127.0.0.1:{port}]", OPTION)


def test_a_recording_holds_the_ros2_topics_as_rosbag2_channels_another_decoder_reads(tmp_path):
    """`--record` writes each `ros2:` stream as rosbag2 does (topic, `ros2msg` schema, `cdr`); mcap-ros2-support,
    which parses the schema text and the CDR itself, reads back the values of the stream's raw channel."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    from hapticop.recording.reading import series
    from tests.runtime_helpers import run_until, steps

    port = _free_port()
    text = SYSTEM.replace("connect: [tcp/127.0.0.1:7447]", f"listen: [tcp/127.0.0.1:{port}]")
    path = tmp_path / "run.mcap"
    # the node's cycles, not a duration: 300 of 5 ms once it runs, however long it took to start
    result = run_until(tmp_path, text, lambda system: steps(system, "ros2") >= 300, "the node's 300th cycle",
                       record=str(path))
    assert result.outcome.status.name == "SUCCESS", result.outcome.reasons
    raw = {name: series(path, name) for name in ("handle_pose", "handle_force")}
    seen = {"/handle/pose": [], "/handle/wrench": []}
    with path.open("rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(topics=list(seen)):
            assert (schema.encoding, channel.message_encoding) == ("ros2msg", "cdr")
            stamp = decoded.header.stamp.sec * 1_000_000_000 + decoded.header.stamp.nanosec
            assert stamp == message.publish_time
            if channel.topic == "/handle/pose":
                assert schema.name == "geometry_msgs/msg/PoseStamped" and decoded.header.frame_id == "falcon"
                p = decoded.pose.position
                seen[channel.topic].append((stamp, [p.x, p.y, p.z]))
            else:
                assert schema.name == "geometry_msgs/msg/WrenchStamped"
                w = decoded.wrench.force
                seen[channel.topic].append((stamp, [w.x, w.y, w.z]))
    for topic, stream, rate in (("/handle/pose", "handle_pose", 100), ("/handle/wrench", "handle_force", 50)):
        by_stamp = dict(zip(raw[stream].publish_ns.tolist(), raw[stream].values.tolist(), strict=True))
        assert len(seen[topic]) >= 10, topic
        for stamp, value in seen[topic]:
            assert by_stamp[stamp] == value, (topic, stamp)
        gaps = [b[0] - a[0] for a, b in zip(seen[topic], seen[topic][1:], strict=False)]
        assert min(gaps) >= 1e9 / rate, topic  # thinned to the topic's declared rate, as the node sends it
    assert_bag_reads_back(path, {"/handle/pose": seen["/handle/pose"], "/handle/wrench": seen["/handle/wrench"],
                                 "/goal": []})


def assert_bag_reads_back(recording, expected: dict[str, list] | None = None, at_least: int = 1) -> dict:
    """The bag beside a recording opens in rosbags' rosbag2 readers (the directory with its metadata.yaml, and
    its MCAP file alone), lists every ROS 2 topic with its type and QoS, and every message decodes: to the
    `(stamp, values)` expected, or, without them, to at least `at_least` messages a topic. Returns the
    decoded messages by topic."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader

    from hapticop.recording.ros2channels import bag_of

    bag = bag_of(recording)
    assert (bag / "metadata.yaml").is_file() and not list(bag.glob("*.part")), sorted(bag.iterdir())
    decoded: dict[str, list] = {}
    with Reader(bag) as directory:
        assert directory.ros_distro == "jazzy" and directory.message_count == sum(
            c.msgcount for c in directory.connections)
    with AnyReader([bag]) as reader:
        topics = {c.topic: c for c in reader.connections}
        if expected is not None:
            assert set(topics) == set(expected), topics
        for connection, time_ns, raw in reader.messages(connections=reader.connections):
            message = reader.deserialize(raw, connection.msgtype)
            stamp = getattr(message, "header", None)
            assert stamp is None or stamp.stamp.sec * 1_000_000_000 + stamp.stamp.nanosec == time_ns
            decoded.setdefault(connection.topic, []).append((time_ns, message))
        for topic, connection in topics.items():
            assert connection.digest.startswith("RIHS01_") and connection.ext.offered_qos_profiles, topic
            count = len(decoded.get(topic, []))
            assert connection.msgcount == count, topic  # metadata.yaml's count is the file's
            assert count == len(expected[topic]) if expected is not None else count >= at_least, (topic, count)
    for topic, values in (expected or {}).items():
        got = []
        for stamp, message in decoded.get(topic, []):
            v = message.pose.position if topic == "/handle/pose" else message.wrench.force
            got.append((stamp, [v.x, v.y, v.z]))
        assert got == values, topic
    with Reader(next(bag.glob("*_0.mcap"))) as alone:  # the bag's file opens by itself too (profile ros2)
        assert {c.topic for c in alone.connections} == set(topics)
        assert sum(1 for _ in alone.messages()) == sum(map(len, decoded.values()))
    return decoded


def test_rates_and_ages_are_written_as_every_period_and_duration_of_a_composition():
    """`rate: 100Hz` and `rate: 10ms` are one period; a bare number or a rate above 1 kHz is a located finding."""
    expanded = [_plain(expand(YAML(typ="rt").load(SYSTEM.replace("rate: 100Hz", spelling)), declared_port)[0])
                for spelling in ("rate: 100Hz", "rate: 10ms", "rate: 0.1kHz")]
    assert all(e["activities"]["ros2"]["params"]["publish"]["handle_pose"]["rate"] == "10ms" for e in expanded)
    found = _findings(SYSTEM.replace("max_age: 300ms\n    ros2: {", "max_age: 300ms\n    ros2: {max_age: 250ms, "))
    assert found == []
    found = _findings(SYSTEM.replace("rate: 100Hz", "rate: 100"))
    assert len(found) == 1 and found[0].startswith("15 streams.handle_pose.ros2.rate") and "needs a unit" in found[0]
    found = _findings(SYSTEM.replace("rate: 100Hz", "rate: 2kHz"))
    assert len(found) == 1 and found[0].startswith("15 streams.handle_pose.ros2") and "faster than 1kHz" in found[0]
    found = _findings(SYSTEM.replace("rate: 100Hz", "rate_hz: 100"))
    assert len(found) == 1 and "rate_hz" in found[0], found


FLAGS = """
version: 1
name: ros2_flags
ros2: {node: hapticop, listen: [tcp/127.0.0.1:PORT], flags: {rate: 20Hz}}
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, counter]}}
activities:
  mediator: {block: mediator}
  counter: {block: counter, params: {stop_after: 5000}}
"""


def test_the_runs_flags_are_a_string_topic_the_independent_client_lists_and_reads(tmp_path):
    """`ros2: {flags: ...}` alone makes the node: the client lists its std_msgs/msg/String publisher and reads
    every flag of the run as JSON, 'counter.reached' false and then, 5 s in, true."""
    from tests.runtime_helpers import run_until
    from tests.test_ros2_bridge import Client

    port = _free_port()
    client = Client(port, "probe")
    client.wait(lambda line: line.get("ready"), "the client's node up")
    string_hash = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    seen = {"before": False, "after": False, "listed": False}

    def reached(system) -> bool:
        for line in client.lines_since():
            if "flags" in line:
                seen["after" if line["flags"]["counter.reached"] else "before"] = True
            publishers = line.get("endpoints", {}).get("/hapticop/flags", [])
            seen["listed"] |= ["hapticop", "MP", string_hash, "::,10:,:,:,,"] in publishers
        return all(seen.values())

    try:
        run_until(tmp_path, FLAGS.replace("PORT", str(port)), reached, "the flags read before and after the count")
    except AssertionError as error:
        raise AssertionError(f"{error} (seen {seen}; the client's last lines: {client.drain()[-3:]}; "
                             f"its errors: {client.errors()!r})") from None
    finally:
        client.close()


INFER = """\
version: 1
name: inferred
ros2: {node: hapticop, listen: [tcp/127.0.0.1:7447]}
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, ranges, twist]}}
activities:
  mediator: {block: mediator}
  ranges: {block: echo, params: {dtype: float32, shape: [7], unit: m}}
  twist: {block: echo, params: {dtype: float64, shape: [6], unit: "m/s, m/s, m/s, rad/s, rad/s, rad/s"}}
streams:
  scan:
    to: [ranges.input]
    ros2: {topic: /scan, type: sensor_msgs/msg/LaserScan}
  cmd_in:
    to: [twist.input]
    ros2: {topic: /cmd_in, type: geometry_msgs/msg/Twist}
  cmd:
    from: twist.output
    ros2: {topic: /cmd_vel, type: geometry_msgs/msg/Twist}
"""


def test_a_topics_shape_is_taken_from_the_port_it_carries():
    """A scan's length and a full (not planar) twist come from the hapticop port; with no port, a scan's
    length is a located finding."""
    params = _plain(expand(YAML(typ="rt").load(INFER), declared_port)[0])["activities"]["ros2"]["params"]
    assert params["subscribe"]["scan"]["shape"] == [7] and params["publish"]["cmd"]["shape"] == [6]
    assert params["subscribe"]["cmd_in"]["shape"] == [6]
    assert _findings(INFER) == []
    found = _findings(INFER.replace("    to: [ranges.input]\n", ""))
    assert any(f.startswith("12 streams.scan.ros2") and "needs 'shape: [N]'" in f for f in found), found
