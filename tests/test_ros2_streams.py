"""Streams with `ros2:`: the loader's rewrite to a generated ROS 2 node, the checks of a port against its
message (located), and the option end to end against the independent ROS 2 client (tests/ros2_client.py)."""

from __future__ import annotations

from ruamel.yaml import YAML

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
    ros2: {topic: /handle/pose, type: geometry_msgs/msg/PoseStamped, frame_id: falcon, rate_hz: 100}
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
                                       "rate_hz": 100.0, "frame_id": "falcon"},
                       "handle_force": {"topic": "/handle/wrench", "type": "geometry_msgs/msg/WrenchStamped"}},
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
    expanded, found = expand(tree)
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
    ros2: {topic: /cmd_out, type: geometry_msgs/msg/Twist, rate_hz: 50}
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
