"""The simulated world the LIDAR block's built-in simulator scans, found by name.

The world activity opens a `Scene` and keeps the robot's pose in the hallway in it; the lidar
block's `driver: sim` ray-casts from that pose. The pose and the hallway's geometry are also in
shared memory, for a scanner in another process. Everything else the simulators share travels
in declared streams; this goes too once the LIDAR has a simulator of its own that reads the
world's `pose_in_hallway`.
"""

from __future__ import annotations

import os
import pickle
import struct
import threading
from dataclasses import dataclass, field
from multiprocessing.shared_memory import SharedMemory

import numpy as np

from hapticop.sim.hallway import HallwayGeometry, World


@dataclass
class Scene:
    name: str
    geometry: HallwayGeometry
    world: World
    pose: np.ndarray = field(default_factory=lambda: np.zeros(3))  # robot x, y, theta in the world
    shared_pose: SharedMemory | None = None  # where `pose` lives, for simulated devices in other processes


_scenes: dict[str, Scene] = {}
_lock = threading.Lock()

# A scene's shared memory: the robot's pose (3 float64), then the hallway's geometry pickled
# behind its length, so a simulated device in a child process builds the same walls.
_POSE_BYTES, _LENGTH = 24, struct.Struct("<I")


def _shared_name(scene: str, world_pid: int) -> str:
    return f"hapticop-scene-{world_pid}-{scene}"


@dataclass
class SharedScene:
    """What a simulated device in a child process sees of a scene open in the main process."""

    name: str
    geometry: HallwayGeometry
    shared_pose: SharedMemory

    @property
    def pose(self) -> np.ndarray:
        return np.ndarray((3,), dtype=np.float64, buffer=self.shared_pose.buf)


def open_scene(scene: Scene) -> Scene:
    with _lock:
        if scene.name in _scenes:
            raise ValueError(f"a simulated world named '{scene.name}' is already open in this process")
        # The pose in shared memory: a simulated scanner in a process of its own sees the robot move.
        geometry = pickle.dumps(scene.geometry)
        shared = SharedMemory(_shared_name(scene.name, os.getpid()), create=True,
                              size=_POSE_BYTES + _LENGTH.size + len(geometry))
        _LENGTH.pack_into(shared.buf, _POSE_BYTES, len(geometry))
        shared.buf[_POSE_BYTES + _LENGTH.size:_POSE_BYTES + _LENGTH.size + len(geometry)] = geometry
        scene.shared_pose = shared
        scene.pose = np.ndarray(scene.pose.shape, dtype=np.float64, buffer=shared.buf)
        scene.pose[:] = scene.geometry.start
        _scenes[scene.name] = scene
    return scene


def find_scene(name: str) -> Scene | None:
    """The open scene, or None while its world activity has not created it yet."""
    return _scenes.get(name)


def find_shared_scene(name: str) -> Scene | SharedScene | None:
    """The scene in this process, or else the one the parent process opened (the world runs in
    the main process, a device's thread in a child): its geometry and the robot's live pose."""
    scene = _scenes.get(name)
    if scene is not None:
        return scene
    try:
        return attach_scene(_shared_name(name, os.getppid()), name)
    except FileNotFoundError:
        return None


def attach_scene(memory_name: str, name: str = "") -> SharedScene:
    """A scene's shared memory, by its name (FileNotFoundError if it is not open)."""
    shared = SharedMemory(memory_name)
    (length,) = _LENGTH.unpack_from(shared.buf, _POSE_BYTES)
    geometry = pickle.loads(bytes(shared.buf[_POSE_BYTES + _LENGTH.size:_POSE_BYTES + _LENGTH.size + length]))
    return SharedScene(name, geometry, shared)


def close_scene(name: str) -> None:
    with _lock:
        scene = _scenes.pop(name, None)
    if scene is not None and scene.shared_pose is not None:
        scene.pose = scene.pose.copy()  # whoever still looks at the scene sees the last pose
        scene.shared_pose.unlink()  # the mapping itself goes with the process (views may remain)

