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
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, falcon_sim, falcon, spring]}}
activities:
  mediator: {block: mediator}
  falcon: {block: falcon, params: {driver: sim, simulator: falcon_sim}}
  falcon_sim: {block: falcon_simulator}
  spring: {block: spring_damper}
streams:
  position: {from: falcon.position, to: [spring.position]}
  force: {from: spring.force, to: [falcon.force]}
  handle_pose:
    from: falcon.position
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
    assert len(found) == 1 and found[0].startswith("16 streams.handle_pose.ros2.type ros2-unit:"), found
    assert "carries [m/s, m/s, rad/s]" in found[0]
    bad = SYSTEM.replace("type: geometry_msgs/msg/WrenchStamped}", "type: geometry_msgs/msg/WrenchStamped, "
                         "shape: [6]}")
    found = _findings(bad)
    assert len(found) == 1 and found[0].startswith("19 streams.handle_force.ros2.shape ros2-message:"), found
    bad = SYSTEM.replace("type: geometry_msgs/msg/WrenchStamped}", "type: sensor_msgs/msg/LaserScan, shape: [3]}")
    found = _findings(bad)
    assert len(found) == 1 and found[0].startswith("19 streams.handle_force.ros2.type ros2-message:"), found
    assert "does not fit sensor_msgs/msg/LaserScan" in found[0]


def test_a_bad_option_or_node_is_a_located_finding_not_a_rewrite():
    found = _findings(SYSTEM.replace("topic: /goal", "topic: /2goal"))
    assert any(f.startswith("22 streams.goal.ros2") and "not a ROS 2 name" in f for f in found), found
    found = _findings(SYSTEM.replace("frame_id: falcon,", "frame_id: falcon, distro: humble,"))
    assert found == ["16 streams.handle_pose.ros2.distro ros2-distro: distro 'humble' is not the node's 'jazzy'"]
    found = _findings(SYSTEM.replace("    from: falcon.position\n", "    from: falcon.position\n    to: [x.y]\n"))
    assert any(f.startswith("17 streams.handle_pose.ros2 ros2-sides") for f in found), found
    found = _findings(SYSTEM.replace("connect: [tcp/127.0.0.1:7447]", "mode: client"))
    assert any(f.startswith("3 ros2") and "needs 'connect'" in f for f in found), found
    found = _findings(SYSTEM.replace("ros2: {node: operator, domain: 3, connect: [tcp/127.0.0.1:7447]}\n", ""))
    assert any(f.startswith("15 streams.handle_pose.ros2 ros2-node") for f in found), found


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
