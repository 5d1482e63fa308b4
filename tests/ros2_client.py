"""An independent ROS 2 participant for the ROS 2 bridge's tests, written with zenoh-ros2-sdk (which follows
rmw_zenoh on its own), not with hapticop's code: it runs in a process of its own and says what it sees as
JSON lines on its standard output.

    python tests/ros2_client.py PORT probe   # publishes /cmd_in (Twist, 20 Hz), prints /cmd_out, /hapticop/flags
                                             # and the graph
    python tests/ros2_client.py PORT robot   # a planar robot in a corridor: cmd_vel in; odom and scan out
    python tests/ros2_client.py PORT latency # /cmd_in at 20 Hz; the age of each /cmd_stamped on arrival

The SDK computes the type hashes itself from the .msg texts given here (it would clone them from GitHub
otherwise); its CDR is rosbags', as hapticop's is, so the bytes are checked apart too (test_ros2_names).
"""

from __future__ import annotations

import json
import math
import os
import sys
import threading
import time
import traceback
from pathlib import Path

from rosbags.typesys import get_types_from_msg
from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber
from zenoh_ros2_sdk.discovery import get_topic_info, get_topic_names_and_types
from zenoh_ros2_sdk.qos import QosProfile, QosReliability
from zenoh_ros2_sdk.session import ZenohSession
from zenoh_ros2_sdk.utils import get_type_hash

MSGS = {k: v for k, v in json.loads((Path(__file__).parent / "fixtures" / "ros2" / "msgs.json").read_text()).items()
        if not k.startswith("_")}
LOCK = threading.Lock()
CORRIDOR_HALF_WIDTH_M = 1.0  # walls at y = +-1
END_WALL_M = 6.0  # the corridor ends at x = 6
BEAMS = 181  # -90 to 90 degrees, one degree apart


def say(**what) -> None:
    with LOCK:
        sys.stdout.write(json.dumps(what) + "\n")  # the client's protocol, read by the tests, not a figure
        sys.stdout.flush()


def endpoint(kind, topic: str, ros_type: str, port: int, node: str, **extra):
    return kind(topic=topic, msg_type=ros_type, msg_definition=MSGS[ros_type], router_port=port, node_name=node,
                type_hash=get_type_hash(ros_type, msg_definition=MSGS[ros_type], dependencies=MSGS), **extra)


def graph(port: int) -> None:
    """What `ros2 node list`, `ros2 topic list -t` and `ros2 topic info -v` would say, from liveliness tokens."""
    topics = get_topic_names_and_types(router_port=port, timeout=0.5)
    endpoints = {}
    for topic, _ in topics:
        info = get_topic_info(topic, router_port=port, timeout=0.5, verbose=True)
        if info is None:  # listed a moment ago, not found now (a query that timed out): the next pass lists it
            continue
        endpoints[topic] = sorted([e.node_name, "MP", e.type_hash, e.qos] for e in info.publishers) + sorted(
            [e.node_name, "MS", e.type_hash, e.qos] for e in info.subscribers)
    session = ZenohSession.get_instance("127.0.0.1", port)
    nodes = sorted(str(r.ok.key_expr).rsplit("/", 1)[1] for r in session.liveliness.get("@ros2_lv/0/*/*/*/NN/**",
                                                                                         timeout=0.5) if r.ok)
    say(topics=topics, endpoints=endpoints, nodes=nodes)


def probe(port: int, types) -> None:
    vector = types["geometry_msgs/msg/Vector3"]
    cmd_in = endpoint(ROS2Publisher, "/cmd_in", "geometry_msgs/msg/Twist", port, "probe",
                      qos=QosProfile(reliability=QosReliability.BEST_EFFORT, history_depth=1))
    endpoint(ROS2Subscriber, "/cmd_out", "geometry_msgs/msg/Twist", port, "probe",
             callback=lambda m: say(cmd_out=[m.linear.x, m.linear.y, m.angular.z]))
    endpoint(ROS2Subscriber, "/wrench", "geometry_msgs/msg/WrenchStamped", port, "probe",
             callback=lambda m: say(wrench=[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z],
                                    frame=m.header.frame_id, stamp=m.header.stamp.sec + m.header.stamp.nanosec * 1e-9))
    endpoint(ROS2Subscriber, "/hapticop/flags", "std_msgs/msg/String", port, "probe",
             callback=lambda m: say(flags=json.loads(m.data)))
    next_graph = 0.0
    while True:
        cmd_in.publish(linear=vector(x=0.25, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.5))
        if time.monotonic() > next_graph:
            next_graph = time.monotonic() + 0.5
            graph(port)
        time.sleep(0.05)


def latency(port: int, types) -> None:
    """Publishes /cmd_in at 20 Hz; for every /cmd_stamped, how long after its header's stamp it arrived."""
    vector = types["geometry_msgs/msg/Vector3"]
    cmd_in = endpoint(ROS2Publisher, "/cmd_in", "geometry_msgs/msg/Twist", port, "probe")

    def arrived(m) -> None:
        now, stamp = time.time_ns(), m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        say(age_ms=(now - stamp) / 1e6, stamp=stamp)

    endpoint(ROS2Subscriber, "/cmd_stamped", "geometry_msgs/msg/TwistStamped", port, "probe", callback=arrived)
    n = 0
    while True:
        n += 1
        cmd_in.publish(linear=vector(x=0.001 * (n % 100), y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.0))
        time.sleep(0.05)


def robot(port: int, types) -> None:
    """Integrates the newest cmd_vel over the time passed (none for 0.5 s: stop), about 100 Hz; odometry every
    second step, a scan every fifth."""
    t = types
    state = {"x": 0.0, "y": 0.0, "yaw": 0.0, "vx": 0.0, "wz": 0.0, "heard": 0.0}

    def command(m) -> None:
        with LOCK:
            state.update(vx=m.linear.x, wz=m.angular.z, heard=time.monotonic())

    endpoint(ROS2Subscriber, "/cmd_vel", "geometry_msgs/msg/Twist", port, "robot", callback=command)
    odom = endpoint(ROS2Publisher, "/odom", "nav_msgs/msg/Odometry", port, "robot")
    scan = endpoint(ROS2Publisher, "/scan", "sensor_msgs/msg/LaserScan", port, "robot",
                    qos=QosProfile(reliability=QosReliability.BEST_EFFORT, history_depth=5))
    step, tick, collided, last = 0.01, 0, False, time.monotonic()
    while True:
        with LOCK:
            # the time that passed, not the nominal step: a loaded machine slows this loop, not the robot
            now_s = time.monotonic()
            step, last = min(now_s - last, 0.1), now_s
            stale = now_s - state["heard"] > 0.5
            vx, wz = (0.0, 0.0) if stale else (state["vx"], state["wz"])
            state["yaw"] += wz * step
            state["x"] += vx * math.cos(state["yaw"]) * step
            state["y"] += vx * math.sin(state["yaw"]) * step
            x, y, yaw = state["x"], state["y"], state["yaw"]
        collided = collided or x > END_WALL_M - 0.2 or abs(y) > CORRIDOR_HALF_WIDTH_M - 0.2
        now = time.time_ns()
        header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=now // 10**9,
                                          nanosec=now % 10**9), frame_id="odom")
        if tick % 2 == 0:
            pose = t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                               orientation=t["geometry_msgs/msg/Quaternion"](
                                                   x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)))
            vec = t["geometry_msgs/msg/Vector3"]
            import numpy as np

            odom.publish(header=header, child_frame_id="base_link",
                         pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                         twist=t["geometry_msgs/msg/TwistWithCovariance"](
                             twist=t["geometry_msgs/msg/Twist"](linear=vec(x=vx, y=0.0, z=0.0),
                                                               angular=vec(x=0.0, y=0.0, z=wz)),
                             covariance=np.zeros(36)))
            say(odom=[x, y, yaw], cmd=[vx, wz], collided=collided)
        if tick % 5 == 0:
            import numpy as np

            angles = np.radians(np.arange(BEAMS) - 90.0) + yaw
            ranges = np.array([_ray(x, y, a) for a in angles], np.float32)
            header.frame_id = "laser"
            scan.publish(header=header, angle_min=-math.pi / 2, angle_max=math.pi / 2,
                         angle_increment=math.radians(1.0), time_increment=0.0, scan_time=0.05, range_min=0.05,
                         range_max=10.0, ranges=ranges, intensities=np.zeros(0, np.float32))
        tick += 1
        time.sleep(0.01)


def _ray(x: float, y: float, angle: float) -> float:
    """Distance along `angle` to the corridor's walls (y = +-1, x = END_WALL_M); inf beyond 10 m."""
    c, s = math.cos(angle), math.sin(angle)
    hits = []
    if s > 1e-9:
        hits.append((CORRIDOR_HALF_WIDTH_M - y) / s)
    if s < -1e-9:
        hits.append((-CORRIDOR_HALF_WIDTH_M - y) / s)
    if c > 1e-9:
        hits.append((END_WALL_M - x) / c)
    d = min(hits, default=math.inf)
    return d if d <= 10.0 else math.inf


def main() -> None:
    port, role = int(sys.argv[1]), sys.argv[2]
    session = ZenohSession.get_instance("127.0.0.1", port)
    for ros_type, text in MSGS.items():
        session.store.register(get_types_from_msg(text, ros_type))
    say(ready=True)
    {"probe": probe, "robot": robot, "latency": latency}[role](port, session.store.types)


if __name__ == "__main__":
    try:
        main()
    except Exception:  # noqa: BLE001 - said on stderr, and the process ends: the SDK's threads would keep it up
        traceback.print_exc()
        sys.stderr.flush()
        os._exit(1)
