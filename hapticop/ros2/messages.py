"""A port's array as a ROS 2 message, and back: which shapes fit which type, and their CDR bytes.

rosbags holds the definitions and the CDR serialiser; this module only says where a port's elements go
in a message. A type admits a few layouts, told apart by the port's length; their units are fixed, so
`validate` can say a stream does not fit before anything runs:

| type | port | elements |
|---|---|---|
| geometry_msgs/msg/Twist, TwistStamped | float64[3] `m/s, m/s, rad/s` | linear.x, linear.y, angular.z (a planar base) |
| | float64[6] `m/s, m/s, m/s, rad/s, rad/s, rad/s` | linear, angular |
| geometry_msgs/msg/WrenchStamped | float64[3] `N` | force |
| | float64[6] `N, N, N, N m, N m, N m` | force, torque |
| geometry_msgs/msg/PoseStamped | float64[3] `m` | position (orientation: identity) |
| | float64[7] `m, m, m, 1, 1, 1, 1` | position, quaternion x y z w |
| nav_msgs/msg/Odometry | float64[3] `m, m, rad` | x, y, yaw |
| | float64[6] `m, m, rad, m/s, m/s, rad/s` | x, y, yaw, then the body twist vx, vy, wz |
| sensor_msgs/msg/LaserScan | float32[N] `m` | ranges (N fixed, another length refused); angles as a second port |
| sensor_msgs/msg/JointState | float64[N] `rad` | positions, named by the stream |
| std_msgs/msg/Header | float64 `s` | the stamp |

Decoding refuses malformed CDR, another length, and values that are not finite (a scan's infinities
are REP-117's "no return" and "too close", and pass; its NaN does not).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hapticop.ros2.names import Distro, typestore


@dataclass(frozen=True)
class Layout:
    dtype: str
    size: int | None  # None: any length, fixed by the stream (a scan's ranges, joints)
    unit: str
    doc: str

    def fits(self, dtype: str, shape: tuple[int, ...]) -> bool:
        if self.size == 0:
            return dtype == self.dtype and shape == ()
        return dtype == self.dtype and len(shape) == 1 and (self.size is None or shape[0] == self.size) and shape[0] > 0


TWIST = (Layout("float64", 3, "m/s, m/s, rad/s", "linear.x, linear.y, angular.z"),
         Layout("float64", 6, "m/s, m/s, m/s, rad/s, rad/s, rad/s", "linear x y z, angular x y z"))
LAYOUTS: dict[str, tuple[Layout, ...]] = {
    "geometry_msgs/msg/Twist": TWIST,
    "geometry_msgs/msg/TwistStamped": TWIST,
    "geometry_msgs/msg/WrenchStamped": (
        Layout("float64", 3, "N", "force x y z"),
        Layout("float64", 6, "N, N, N, N m, N m, N m", "force x y z, torque x y z")),
    "geometry_msgs/msg/PoseStamped": (
        Layout("float64", 3, "m", "position x y z (orientation: identity)"),
        Layout("float64", 7, "m, m, m, 1, 1, 1, 1", "position x y z, quaternion x y z w")),
    "nav_msgs/msg/Odometry": (
        Layout("float64", 3, "m, m, rad", "x, y, yaw"),
        Layout("float64", 6, "m, m, rad, m/s, m/s, rad/s", "x, y, yaw, body vx, vy, wz")),
    "sensor_msgs/msg/LaserScan": (Layout("float32", None, "m", "ranges"),),
    "sensor_msgs/msg/JointState": (Layout("float64", None, "rad", "positions"),),
    "std_msgs/msg/Header": (Layout("float64", 0, "s", "the stamp"),),
}


def layout_of(ros_type: str, dtype: str, shape: tuple[int, ...]) -> Layout | None:
    return next((layout for layout in LAYOUTS.get(ros_type, ()) if layout.fits(dtype, shape)), None)


def describe(ros_type: str) -> str:
    """The layouts a type admits, for a message that says what would fit."""
    return "; ".join(f"{lay.dtype}{'[N]' if lay.size is None else '' if lay.size == 0 else [lay.size]} "
                     f"[{lay.unit}] ({lay.doc})" for lay in LAYOUTS[ros_type])


@dataclass(frozen=True)
class ScanGeometry:
    """What a LaserScan says besides its ranges: where its beams point and what it can measure."""

    angle_min_rad: float = -math.pi / 2
    angle_increment_rad: float = math.pi / 180
    range_min_m: float = 0.05
    range_max_m: float = 10.0
    scan_time_s: float = 0.0


class Codec:
    """One stream's message type and layout in one distribution: arrays to CDR bytes and back."""

    def __init__(self, ros_type: str, distro: Distro, dtype: str, shape: tuple[int, ...], frame_id: str = "",
                 scan: ScanGeometry | None = None, names: tuple[str, ...] = ()) -> None:
        layout = layout_of(ros_type, dtype, shape)
        if layout is None:
            raise ValueError(f"{dtype}{list(shape)} does not fit {ros_type}: {describe(ros_type)}")
        self.ros_type, self.layout, self.frame_id = ros_type, layout, frame_id
        self.scan = scan or ScanGeometry()
        self.names = list(names)
        self.store = typestore(distro)
        self.types = self.store.types
        self.size = 0 if not shape else shape[0]

    # -- arrays to messages -----------------------------------------------------------
    def encode(self, value: np.ndarray, stamp_ns: int) -> bytes:
        return bytes(self.store.serialize_cdr(self.message(value, stamp_ns), self.ros_type))

    def message(self, value: np.ndarray, stamp_ns: int):
        t, v = self.types, value
        header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](
            sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000), frame_id=self.frame_id)
        vector, n = t["geometry_msgs/msg/Vector3"], self.size
        kind = self.ros_type.split("/")[-1]
        if kind in ("Twist", "TwistStamped"):
            lin, ang = ((v[0], v[1], 0.0), (0.0, 0.0, v[2])) if n == 3 else (v[:3], v[3:])
            twist = t["geometry_msgs/msg/Twist"](linear=vector(*map(float, lin)), angular=vector(*map(float, ang)))
            return twist if kind == "Twist" else t["geometry_msgs/msg/TwistStamped"](header=header, twist=twist)
        if kind == "WrenchStamped":
            torque = v[3:] if n == 6 else (0.0, 0.0, 0.0)
            wrench = t["geometry_msgs/msg/Wrench"](force=vector(*map(float, v[:3])),
                                                  torque=vector(*map(float, torque)))
            return t["geometry_msgs/msg/WrenchStamped"](header=header, wrench=wrench)
        if kind == "PoseStamped":
            quaternion = v[3:7] if n == 7 else (0.0, 0.0, 0.0, 1.0)
            return t["geometry_msgs/msg/PoseStamped"](header=header, pose=self._pose(v[:3], quaternion))
        if kind == "Odometry":
            yaw = float(v[2])
            pose = self._pose((v[0], v[1], 0.0), (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))
            body = (v[3], v[4], v[5]) if n == 6 else (0.0, 0.0, 0.0)
            twist = t["geometry_msgs/msg/Twist"](linear=vector(float(body[0]), float(body[1]), 0.0),
                                                 angular=vector(0.0, 0.0, float(body[2])))
            return t["nav_msgs/msg/Odometry"](
                header=header, child_frame_id="base_link",
                pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
        if kind == "LaserScan":
            s = self.scan
            return t["sensor_msgs/msg/LaserScan"](
                header=header, angle_min=s.angle_min_rad, angle_max=s.angle_min_rad + (n - 1) * s.angle_increment_rad,
                angle_increment=s.angle_increment_rad, time_increment=0.0, scan_time=s.scan_time_s,
                range_min=s.range_min_m, range_max=s.range_max_m, ranges=np.asarray(v, np.float32),
                intensities=np.zeros(0, np.float32))
        if kind == "JointState":
            names = self.names or [f"joint{i}" for i in range(n)]
            return t["sensor_msgs/msg/JointState"](header=header, name=names, position=np.asarray(v, np.float64),
                                                   velocity=np.zeros(0), effort=np.zeros(0))
        seconds = float(v)  # std_msgs/msg/Header: its own stamp
        header.stamp.sec, header.stamp.nanosec = int(seconds), int(round((seconds % 1) * 1e9)) % 1_000_000_000
        return header

    def _pose(self, position, quaternion):
        t = self.types
        return t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](*map(float, position)),
                                           orientation=t["geometry_msgs/msg/Quaternion"](*map(float, quaternion)))

    # -- messages to arrays -----------------------------------------------------------
    def decode(self, data: bytes, out: np.ndarray, angles: np.ndarray | None = None) -> str | None:
        """Fill `out` (and a scan's `angles`) from CDR bytes; why they were refused, or None."""
        try:
            msg = self.store.deserialize_cdr(data, self.ros_type)
        except Exception:  # noqa: BLE001 - whatever the parser trips on, the bytes are malformed
            return "malformed CDR"
        kind, n = self.ros_type.split("/")[-1], self.size
        if kind in ("Twist", "TwistStamped"):
            twist = msg if kind == "Twist" else msg.twist
            lin, ang = twist.linear, twist.angular
            values = [lin.x, lin.y, ang.z] if n == 3 else [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z]
        elif kind == "WrenchStamped":
            f, q = msg.wrench.force, msg.wrench.torque
            values = [f.x, f.y, f.z] + ([q.x, q.y, q.z] if n == 6 else [])
        elif kind == "PoseStamped":
            p, q = msg.pose.position, msg.pose.orientation
            values = [p.x, p.y, p.z] + ([q.x, q.y, q.z, q.w] if n == 7 else [])
        elif kind == "Odometry":
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            tw = msg.twist.twist
            values = [p.x, p.y, yaw] + ([tw.linear.x, tw.linear.y, tw.angular.z] if n == 6 else [])
        elif kind == "LaserScan":
            if len(msg.ranges) != n:
                return f"{len(msg.ranges)} ranges, not {n}"
            if np.isnan(msg.ranges).any() or not all(map(math.isfinite, (msg.angle_min, msg.angle_increment))):
                return "not finite"
            np.copyto(out, msg.ranges)
            if angles is not None:
                angles[:] = msg.angle_min + np.arange(n) * msg.angle_increment
            return None
        elif kind == "JointState":
            if len(msg.position) != n:
                return f"{len(msg.position)} positions, not {n}"
            values = msg.position
        else:
            values = msg.stamp.sec + msg.stamp.nanosec * 1e-9
        array = np.asarray(values, np.float64)
        if not np.isfinite(array).all():
            return "not finite"
        out[...] = array.reshape(out.shape)
        return None


STRING = "std_msgs/msg/String"


def encode_string(distro: Distro, text: str) -> bytes:
    """A `std_msgs/msg/String` in CDR (the run's flags: not a port, so no layout)."""
    store = typestore(distro)
    return bytes(store.serialize_cdr(store.types[STRING](data=text), STRING))
