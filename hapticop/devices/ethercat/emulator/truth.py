"""Where the emulated robot truly is, shared with the simulated world of another process.

The emulator owns the simulated ropod; the hallway world that judges the run and feeds the
simulated LIDAR lives in the composition's process. The emulator writes the robot's pose
and twist into a small file in /dev/shm after every physics step; a reader maps it. A
sequence counter makes each read consistent: odd while a write is under way.
Layout, float64: [sequence, time s, x, y, theta, vx, vy, wz].
"""

from __future__ import annotations

import mmap
import os
from pathlib import Path

import numpy as np

__all__ = ["TruthWriter", "TruthReader", "truth_path", "TRUTH_ENV"]

_SIZE = 8 * 8


TRUTH_ENV = "HAPTICOP_ECAT_TRUTH"  # set by `hapticop ethercat sandbox` for the command it runs


def truth_path(interface: str) -> Path:
    """Where the segment on `interface` publishes: the sandbox's own file when run inside one
    (two sandboxes on one machine each have an interface of the same name), else /dev/shm."""
    return Path(os.environ.get(TRUTH_ENV) or Path("/dev/shm") / f"hapticop-ecat-{interface}.truth")


class TruthWriter:
    def __init__(self, path: Path):
        self.path = Path(path)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            os.ftruncate(fd, _SIZE)
            self._map = mmap.mmap(fd, _SIZE)
        finally:
            os.close(fd)
        self.values = np.frombuffer(self._map, np.float64)

    def write(self, t_s: float, pose: np.ndarray, twist: np.ndarray) -> None:
        v = self.values
        v[0] += 1.0
        v[1] = t_s
        v[2:5] = pose
        v[5:8] = twist
        v[0] += 1.0

    def close(self) -> None:
        del self.values
        self._map.close()
        self.path.unlink(missing_ok=True)


class TruthReader:
    def __init__(self, path: Path):
        self.path = Path(path)
        fd = os.open(self.path, os.O_RDONLY)
        try:
            self._map = mmap.mmap(fd, _SIZE, prot=mmap.PROT_READ)
        finally:
            os.close(fd)
        self.values = np.frombuffer(self._map, np.float64)
        self._copy = np.zeros(8)

    def read(self, pose_out: np.ndarray, twist_out: np.ndarray) -> float:
        """Copy a consistent pose and twist; returns the sequence (0: nothing written yet)."""
        for _ in range(100):
            np.copyto(self._copy, self.values)
            if self._copy[0] % 2 == 0 and self.values[0] == self._copy[0]:
                break
        pose_out[:] = self._copy[2:5]
        twist_out[:] = self._copy[5:8]
        return float(self._copy[0])

    def close(self) -> None:
        del self.values
        self._map.close()
