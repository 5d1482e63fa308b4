"""Novint Falcon device library: frame codec, kinematics, homing and a simulator.

Facts come from docs/devices/falcon.md and docs/devices/falcon-kinematics.md; the
Falcon block composes these pieces, none of them knows about blocks.
"""

from hapticop.devices.falcon.codec import (
    FRAME_SIZE,
    MOTOR_LIMIT,
    Button,
    Command,
    Flag,
    FrameCodec,
    FrameError,
    FrameReader,
    Status,
    is_valid_frame,
    new_frame,
)
from hapticop.devices.falcon.homing import Homing
from hapticop.devices.falcon.kinematics import FalconKinematics
from hapticop.devices.falcon.mechanism import WORKSPACE_BOX_M, WORKSPACE_CENTRE_M, Drive, Geometry
from hapticop.devices.falcon.simulated import SimulatedFalcon

__all__ = [
    "FRAME_SIZE", "MOTOR_LIMIT", "Button", "Command", "Flag", "FrameCodec", "FrameError",
    "FrameReader", "Status", "is_valid_frame", "new_frame", "Homing", "WORKSPACE_BOX_M",
    "WORKSPACE_CENTRE_M", "Drive", "FalconKinematics", "Geometry", "SimulatedFalcon",
]
