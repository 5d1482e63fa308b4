"""The hallway experiment's log: what a 1 kHz loop records of a run for its metrics (docs/hallway-experiment.md §5).

Why: every condition is compared on numbers computed after the run, so the loop only has to
record. `TrajectoryRecorder` is that record: preallocated, appended to without allocating,
saved as .npz; `as_channels` reads the channels back from a recorder or a loaded file.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

CHANNELS: dict[str, tuple[tuple[int, ...], type]] = {
    "t": ((), np.float64),  # time [s]
    "pose": ((3,), np.float64),  # robot x, y [m], theta [rad], world frame
    "robot_velocity": ((2,), np.float64),  # measured v [m/s], omega [rad/s]
    "cmd": ((2,), np.float64),  # the operator's command u_cmd = (v, omega) from the handle
    "cmd_exec": ((2,), np.float64),  # the command executed after the safety layer, u_exec
    "handle_position": ((3,), np.float64),  # Falcon handle p [m], device frame
    "handle_velocity": ((3,), np.float64),  # dp/dt [m/s]
    "force_env": ((3,), np.float64),  # environmental force F_env on the handle [N]
    "force_hand": ((3,), np.float64),  # the hand's force on the handle [N]
    "force_device": ((3,), np.float64),  # the whole force sent to the device, after saturation [N]
    "clearance": ((), np.float64),  # footprint clearance to all static geometry [m] (MuJoCo's)
    "front_clearance": ((), np.float64),  # ... to a hallway's end wall [m]
    "side_clearance": ((), np.float64),  # ... to everything else [m]
    "pc_power": ((), np.float64),  # power the passivity controller dissipates [W]
    "scan": ((), np.bool_),  # a new scan reached the force model in this cycle
    "risk_true": ((), np.float64),  # ground-truth risk rho* from the undelayed true state
}
"""What a run may log. A channel is logged every cycle or never: only "t" and "pose" are required."""


class TrajectoryRecorder:
    """A run's log in arrays of fixed capacity; `append` copies one cycle in and allocates nothing.

    A full recorder drops further samples and counts them in `dropped` rather than raising in a real-time loop.
    """

    def __init__(self, capacity: int, meta: Mapping[str, object] | None = None):
        if capacity < 1:
            raise ValueError("capacity must be at least one sample")
        self.capacity = capacity
        self.meta: dict[str, object] = dict(meta or {})
        self.n = 0
        self.dropped = 0
        self._data = {k: np.zeros((capacity, *shape), dtype) for k, (shape, dtype) in CHANNELS.items()}
        self._written = {k: k in ("t", "pose") for k in CHANNELS}
        d = self._data
        self.t, self.pose, self.robot_velocity = d["t"], d["pose"], d["robot_velocity"]
        self.cmd, self.cmd_exec = d["cmd"], d["cmd_exec"]
        self.handle_position, self.handle_velocity = d["handle_position"], d["handle_velocity"]
        self.force_env, self.force_hand, self.force_device = d["force_env"], d["force_hand"], d["force_device"]
        self.clearance, self.pc_power, self.scan, self.risk_true = (
            d["clearance"], d["pc_power"], d["scan"], d["risk_true"])
        self.front_clearance, self.side_clearance = d["front_clearance"], d["side_clearance"]

    def append(
        self,
        t: float,
        pose: ArrayLike,
        *,
        robot_velocity: ArrayLike | None = None,
        cmd: ArrayLike | None = None,
        cmd_exec: ArrayLike | None = None,
        handle_position: ArrayLike | None = None,
        handle_velocity: ArrayLike | None = None,
        force_env: ArrayLike | None = None,
        force_hand: ArrayLike | None = None,
        force_device: ArrayLike | None = None,
        clearance: float | None = None,
        front_clearance: float | None = None,
        side_clearance: float | None = None,
        pc_power: float | None = None,
        scan: bool | None = None,
        risk_true: float | None = None,
    ) -> bool:
        """Copy one cycle in; False (and `dropped` + 1) when full."""
        i = self.n
        if i >= self.capacity:
            self.dropped += 1
            return False
        w = self._written
        self.t[i] = t
        self.pose[i] = pose
        if robot_velocity is not None:
            self.robot_velocity[i] = robot_velocity
            w["robot_velocity"] = True
        if cmd is not None:
            self.cmd[i] = cmd
            w["cmd"] = True
        if cmd_exec is not None:
            self.cmd_exec[i] = cmd_exec
            w["cmd_exec"] = True
        if handle_position is not None:
            self.handle_position[i] = handle_position
            w["handle_position"] = True
        if handle_velocity is not None:
            self.handle_velocity[i] = handle_velocity
            w["handle_velocity"] = True
        if force_env is not None:
            self.force_env[i] = force_env
            w["force_env"] = True
        if force_hand is not None:
            self.force_hand[i] = force_hand
            w["force_hand"] = True
        if force_device is not None:
            self.force_device[i] = force_device
            w["force_device"] = True
        if clearance is not None:
            self.clearance[i] = clearance
            w["clearance"] = True
        if front_clearance is not None:
            self.front_clearance[i] = front_clearance
            w["front_clearance"] = True
        if side_clearance is not None:
            self.side_clearance[i] = side_clearance
            w["side_clearance"] = True
        if pc_power is not None:
            self.pc_power[i] = pc_power
            w["pc_power"] = True
        if scan is not None:
            self.scan[i] = scan
            w["scan"] = True
        if risk_true is not None:
            self.risk_true[i] = risk_true
            w["risk_true"] = True
        self.n = i + 1
        return True

    def arrays(self) -> dict[str, np.ndarray]:
        """Views of the recorded part of every channel that was written."""
        return {k: a[: self.n] for k, a in self._data.items() if self._written[k]}

    def save(self, path: str | Path) -> Path:
        """Write the recorded channels and `meta` (as JSON) to a compressed .npz."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        np.savez_compressed(path, __meta__=np.array(json.dumps(self.meta)), **self.arrays())
        return path

    @classmethod
    def load(cls, path: str | Path, capacity: int | None = None) -> TrajectoryRecorder:
        """Read a saved log back; capacity defaults to the number of samples in it."""
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["__meta__"]))
            arrays = {k: z[k] for k in z.files if k != "__meta__"}
        unknown = set(arrays) - set(CHANNELS)
        if unknown:
            raise ValueError(f"{path}: unknown channels {sorted(unknown)}")
        n = len(arrays["t"])
        rec = cls(max(capacity or n, n, 1), meta)
        for k, a in arrays.items():
            rec._data[k][:n] = a
            rec._written[k] = True
        rec.n = n
        return rec


def as_channels(data: TrajectoryRecorder | Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The logged channels of a recorder, or of a mapping such as a loaded .npz (other keys are ignored)."""
    if isinstance(data, TrajectoryRecorder):
        return data.arrays()
    return {k: np.asarray(data[k]) for k in data.keys() if k in CHANNELS}
