"""The Novint Falcon haptic device: handle position in, motor forces out, at 1 kHz.

Geometry defaults to libnifalcon's values so its reference data applies
(../shared/reference/falcon-kinematics.md).
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port, RateRange


class FalconGeometry(Params):
    """Stamper's parallel-mechanism dimensions in metres (libnifalcon's signs)."""

    a: float = 0.060
    b: float = 0.1025
    c: float = 0.01443
    d: float = 0.01125
    e: float = 0.01125
    f: float = -0.025
    r: float = 0.0400
    s: float = -0.02309
    leg_angles_deg: tuple[float, float, float] = (105.0, -15.0, -135.0)


class FalconParams(Params):
    driver: Literal["sim", "usb"] = Field("sim", description="'sim': simulated handle over the real frame codec")
    device_index: int = Field(0, ge=0, description="which Falcon, when several are on USB")
    firmware: str | None = Field(None, description="path to Novint's firmware image (usb driver); never shipped")
    homing: bool = Field(True, description="home the encoders in capability configuration")
    geometry: FalconGeometry = Field(default_factory=FalconGeometry)


class Falcon(Block):
    Params = FalconParams
    inputs = {"force": Port("float64", (3,), "N", "force to render at the handle, device frame")}
    outputs = {
        "position": Port("float64", (3,), "m", "handle position, device frame, origin at the workspace centre"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity, differentiated from position"),
        "buttons": Port("uint8", (), "1", "button bit mask"),
    }
    flags_written = {"frames_ok": "frames arrive and decode (false after 100 ms without one)"}
    rate = RateRange(900.0, 1100.0, "the Falcon firmware exchanges frames at about 1 kHz and holds a force only 100 ms")
