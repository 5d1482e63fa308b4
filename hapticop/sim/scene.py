"""The simulated world the device simulators of one process share.

Real devices share the real world: the LIDAR sees the hallway where the robot actually is,
and the operator feels what the Falcon renders. The simulators share a `Scene` instead,
found by name: the world activity opens it, the simulated ropod writes the robot's pose
into it, the simulated LIDAR ray-casts from that pose, and the simulated Falcon's operator
holds the handle in it. The blocks themselves still know nothing of each other.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass, field

import numpy as np

from hapticop.sim.hallway import HallwayGeometry, World
from hapticop.sim.operator import BlindOperator


@dataclass
class Scene:
    name: str
    geometry: HallwayGeometry
    world: World
    operator: BlindOperator
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))  # robot x, y, theta in the world
    twist: np.ndarray = field(default_factory=lambda: np.zeros(3))  # robot vx, vy, wz (robot frame)
    handle_position: np.ndarray = field(default_factory=lambda: np.zeros(3))  # true handle position (device frame)
    handle_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    device_force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # what the Falcon renders
    environment_force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # its obstacle part: what the operator reacts to
    hand_force: np.ndarray = field(default_factory=lambda: np.zeros(3))  # what the operator applies
    operator_since_ns: int | None = None  # when the operator was told to drive; None: hands resting

    def operator_time(self, now_ns: int) -> float:
        """Seconds since the operator started driving (the operator's and the judge's clock)."""
        return 0.0 if self.operator_since_ns is None else (now_ns - self.operator_since_ns) / 1e9


_scenes: dict[str, Scene] = {}
_lock = threading.Lock()


def open_scene(scene: Scene) -> Scene:
    with _lock:
        if scene.name in _scenes:
            raise ValueError(f"a simulated world named '{scene.name}' is already open in this process")
        scene.pose[:] = scene.geometry.start
        _scenes[scene.name] = scene
    return scene


def find_scene(name: str) -> Scene | None:
    """The open scene, or None while its world activity has not created it yet."""
    return _scenes.get(name)


def close_scene(name: str) -> None:
    with _lock:
        _scenes.pop(name, None)


def place(start: tuple[float, float, float], moved: np.ndarray, out: np.ndarray) -> np.ndarray:
    """The robot's pose in the hallway: its start pose composed with how far it has moved
    (`moved` = [x, y, theta] from where it started, in the start frame), into `out`."""
    sx, sy, st = start
    rx, ry, rt = float(moved[0]), float(moved[1]), float(moved[2])
    c, s = math.cos(st), math.sin(st)
    out[0] = sx + c * rx - s * ry
    out[1] = sy + s * rx + c * ry
    out[2] = st + rt
    return out
