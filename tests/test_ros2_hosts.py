"""`ros2:` streams in a composition with `hosts:`: the ROS 2 node runs on the host its `host:` names, and a
stream between it and a port on another host crosses the hosts' link like any other.

Two hosts on loopback, each a `hapticop compose --host` of its own: the echo on host `a`, the ROS 2 node on
host `b`. The independent client (tests/ros2_client.py, zenoh-ros2-sdk) publishes /cmd_in to b's node; the
twist crosses to a, is echoed, crosses back and comes out as /cmd_out, which the client decodes.
"""

from __future__ import annotations

import textwrap

from hapticop.validation import validate_text
from tests.test_ros2_bridge import TWIST, Client
from tests.test_teleop_network import _free_port, start, stop, wait_for

SYSTEM = """\
version: 1
name: ros2_hosts
security: {insecure: true}
hosts:
  a: {endpoints: [tcp/127.0.0.1:PORT_A]}
  b: {endpoints: [tcp/127.0.0.1:PORT_B]}
ros2: {node: hapticop, host: b, listen: [tcp/127.0.0.1:PORT_ROS], flags: {}}
threads:
  main_a: {period: 1ms, deploy: main, host: a, schedules: {0: [mediator, echo]}}
  main_b: {period: 1ms, deploy: main, host: b, schedules: {0: [mediator]}}
activities:
  mediator: {block: mediator}
  echo: {block: echo, params: {dtype: float64, shape: [3], unit: "m/s, m/s, rad/s"}}
streams:
  cmd_in:
    to: [echo.input]
    max_age: 300ms
    network: {priority: real_time, deadline: 200ms, stale: zero}
    ros2: {topic: /cmd_in, type: geometry_msgs/msg/Twist, qos: {reliability: best_effort, depth: 1}}
  cmd_out:
    from: echo.output
    max_age: 300ms
    network: {priority: real_time, deadline: 200ms, stale: zero}
    ros2: {topic: /cmd_out, type: geometry_msgs/msg/Twist, rate: 50Hz}
"""


def test_a_ros2_node_on_one_host_is_validated_with_the_hosts():
    text = SYSTEM.replace("PORT_A", "7461").replace("PORT_B", "7462").replace("PORT_ROS", "7463")
    validated = validate_text(text)
    assert validated.report.ok, [d.to_text() for d in validated.report.diagnostics]
    shares = {host: part.graph.loaded.composition for host, part in validated.hosts.items()}
    assert "ros2" not in shares["a"].activities and shares["a"].ros2 is None  # one node, b's, flags and all
    params = shares["b"].activities["ros2"].params
    assert set(params["publish"]) == {"cmd_out"} and set(params["subscribe"]) == {"cmd_in"} and "flags" in params
    found = validate_text(text.replace(" host: b,", ""), file="sys.yaml").report.diagnostics
    assert any(d.rule == "ros2-host" and d.line == 7 and "add 'host:' (a, b)" in d.to_text() for d in found), [
        d.to_text() for d in found]


def test_a_twist_from_ros2_crosses_to_the_other_host_and_back(tmp_path):
    ports = {name: _free_port() for name in ("PORT_A", "PORT_B", "PORT_ROS")}
    text = SYSTEM
    for name, port in ports.items():
        text = text.replace(name, str(port))
    path = tmp_path / "ros2_hosts.yaml"
    path.write_text(textwrap.dedent(text))
    client = Client(ports["PORT_ROS"], "probe")
    hosts = [start(path, host, tmp_path / f"run-{host}") for host in ("a", "b")]
    try:
        def echoed() -> bool:
            lines = client.drain()
            listed = any(["/cmd_out", [TWIST]] in line.get("topics", []) and "hapticop" in line.get("nodes", [])
                         for line in lines)
            return listed and any(line.get("cmd_out") == [0.25, 0.0, 0.5] for line in lines)

        try:
            wait_for("the client's twist echoed back across both hosts", echoed, hosts)
        except AssertionError as error:
            raise AssertionError(f"{error} (the client's last lines: {client.drain()[-2:]}; its errors: "
                                 f"{client.errors()!r})") from None
    finally:
        outputs = [stop(process) for process in hosts]
        client.close()
    b_log = (tmp_path / "run-b" / "system.log").read_text()
    a_log = (tmp_path / "run-a" / "system.log").read_text()
    assert "ros2" in b_log and "'ros2'" not in a_log.split("activities", 1)[0], outputs  # the node is b's alone
