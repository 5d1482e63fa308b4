"""The Novint Falcon haptic device: handle position in, motor forces out, at 1 kHz.

Geometry defaults to libnifalcon's values so its reference data applies
(docs/devices/falcon-kinematics.md). The block speaks the Falcon's 16-byte frames on a
link that `driver` chooses: `usb` is the USB driver on a real Falcon (or, with
`usb_backend: virtual`, on the virtual USB Falcon the tests use); `sim` sends the same frames
to the activity named by `simulator`, which simulates the Falcon and whoever holds it.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

from hapticop.blocks.base import Block
from hapticop.blocks.interface import DeviceParams, Port, RateRange
from hapticop.devices.falcon import WORKSPACE_CENTRE_M, FalconKinematics, FrameCodec, Homing, Status, new_frame
from hapticop.devices.falcon.link import DatagramFalconLink, FalconLink
from hapticop.devices.falcon.mechanism import Geometry
from hapticop.devices.link import DatagramLink

NO_FRAME_NS = -(1 << 62)
"""The time of the last good frame before any has come: long enough ago that `frames_ok` is false."""


class FalconParams(DeviceParams):
    simulated_by = "a falcon_simulator"
    driver: Literal["usb", "sim"] = Field("usb", description="'usb': a Falcon on USB; 'sim': the activity "
                                          "named by 'simulator', over the real frame codec")
    device_index: int = Field(0, ge=0, description="which Falcon, when several are on USB")
    firmware: str | None = Field(None, description="path to Novint's firmware image (usb driver); never shipped")
    firmware_sha256: str | None = Field(
        None, description="accept this image instead of Novint's known ones (usb driver): you vouch for it")
    usb_backend: Literal["libusb", "virtual"] = Field(
        "libusb", description="usb driver: 'libusb' for a real Falcon, 'virtual' for the simulated USB device")
    geometry: Geometry = Field(default_factory=Geometry, description="the mechanism's dimensions")

    @field_validator("firmware_sha256")
    @classmethod
    def _is_sha256(cls, value: str | None) -> str | None:
        if value is not None and (len(value) != 64 or any(c not in "0123456789abcdefABCDEF" for c in value)):
            raise PydanticCustomError("sha256", "'firmware_sha256' must be a SHA-256 digest: 64 hex digits")
        return value

    @model_validator(mode="after")
    def _usb_needs_firmware(self) -> FalconParams:
        if self.driver == "usb" and not self.firmware:
            raise PydanticCustomError(
                "usb_firmware", "driver 'usb' needs 'firmware': the path to Novint's Falcon firmware image "
                "(nvent_firmware.bin, from Novint's installer or a libnifalcon checkout; hapticop never ships it)")
        return self


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
    needs = {"simulator": "falcon_device"}

    @classmethod
    def preflight(cls, params: FalconParams, timeout_s: float) -> str | None:
        """A real Falcon: its firmware image readable, and the Falcon on USB."""
        if params.driver != "usb" or params.usb_backend != "libusb":
            return None
        from hapticop.devices.falcon.firmware import FirmwareError, read_firmware
        from hapticop.devices.falcon.usb_driver import find_falcons, system_backend
        from hapticop.devices.falcon.usb_errors import FalconUsbError

        problems = []
        try:
            read_firmware(params.firmware, params.firmware_sha256)
        except FirmwareError as error:
            problems.append(str(error))
        try:
            found = len(find_falcons(system_backend()))
        except FalconUsbError as error:
            problems.append(f"cannot look for a Falcon on USB: {error}")
        else:
            if found <= params.device_index:
                problems.append("no Falcon on USB (no device 0403:CB48)" if found == 0 else
                                f"Falcon {params.device_index} asked for, but {found} on USB")
        return "; ".join(problems) or None

    # -- life cycle -------------------------------------------------------------------------
    def create(self) -> None:
        self.codec, self.status, self.command = FrameCodec(), Status(), new_frame()
        self.centre_xyz = tuple(WORKSPACE_CENTRE_M)
        self.motor = np.zeros(3, dtype=np.int64)
        self.absolute = np.zeros(3)
        self.link: FalconLink | None = None  # from resource configuration on
        self.open = self.frames_ok = False
        self.virtual = None  # the virtual USB Falcon (usb_backend: virtual), for tests to look at
        self._fresh()

    def _fresh(self) -> None:
        """What a newly opened Falcon starts from: not homed, no position, the parameters' geometry."""
        self.kinematics, self.homing = FalconKinematics(self.params.geometry), Homing()
        self.position = (0.0, 0.0, 0.0)  # device frame, workspace origin: last published, as floats
        self.fk_ok = self.framed = False
        self.opened_ns = self.last_read_ns = self.clock.now_ns()
        self.last_frame_ns = NO_FRAME_NS  # opening is no frame: `frames_ok` rises with the first one

    def configure_resources(self) -> bool:
        if self.open:  # configured before, and now with other parameters: a link of their own
            self.link.close()
            self.link, self.open = None, False
        if self.link is None:
            self.link = self._link()
        if not self.link.ready():
            return False  # opening, and maybe loading firmware, on a helper thread
        self._fresh()
        self.open = True
        self.log.info("Falcon link open (driver %s); %s", self.params.driver, Homing.INSTRUCTIONS)
        return True

    def _link(self) -> FalconLink:
        """The link `driver` chooses."""
        p = self.params
        if p.driver == "sim":
            return DatagramFalconLink(DatagramLink.host(self.run_dir, p.simulator, memory=self.clock.virtual))
        from hapticop.devices.falcon.firmware import read_firmware
        from hapticop.devices.falcon.usb_driver import system_backend
        from hapticop.devices.falcon.usb_link import UsbLink, virtual_falcon

        image = read_firmware(p.firmware, p.firmware_sha256)  # a wrong file fails here, at once and clearly
        if p.usb_backend == "virtual":
            self.virtual, backend = virtual_falcon(p.geometry, self.clock.now_ns, not self.clock.virtual, self.rng)
        else:
            backend = system_backend()
        return UsbLink(image, p.device_index, backend, self.log)

    def configure_capabilities(self) -> bool:
        """Homing: someone pulls the grip out, then pushes it in (docs/devices/falcon.md §6)."""
        self._receive()
        self._send(forces=False)
        if self.homing.homed:
            self.log.info("homed after %.2f s", (self.clock.now_ns() - self.opened_ns) / 1e9)
        return self.homing.homed

    def compute(self) -> None:
        """Read: the status frame answering the last command. The force goes out in `flush`,
        once the haptic controller has computed it from this reading."""
        self._receive()

    def flush(self) -> None:
        """Write: the command frame with the force this cycle computed."""
        self._send(forces=True)

    def pausing(self) -> None:
        self._receive()
        self._send(forces=False)

    def clean(self) -> None:
        if self.open:
            self._receive()
            self._send(forces=False)  # a last frame with zero forces
            self.frames_ok = self.flags["frames_ok"] = False
            self.open = False
        if self.link is not None:
            self.link.close()
            self.link = None

    # -- the frames -------------------------------------------------------------------------
    def _receive(self) -> None:
        """The status frame answering the last command: encoders in, then kinematics."""
        now = self.clock.now_ns()
        if not self.link.receive(self.status):
            self._frames(now)
            return
        self.last_frame_ns = now
        self.homing.update(self.status)
        if self.homing.just_homed:
            self.kinematics.reset()  # the counts just became absolute
        self.fk_ok = self.kinematics.forward(self.status.encoders, self.absolute)
        if self.fk_ok:  # position from the workspace centre, velocity by difference: on floats
            dt = (now - self.last_read_ns) / 1e9 or 1e-3
            (x, y, z), (cx, cy, cz), (px, py, pz) = self.absolute.tolist(), self.centre_xyz, self.position
            x, y, z = x - cx, y - cy, z - cz
            self.position = (x, y, z)
            out = self.outputs
            position, velocity = out.position.value, out.velocity.value
            position[0], position[1], position[2] = x, y, z
            velocity[0], velocity[1], velocity[2] = (x - px) / dt, (y - py) / dt, (z - pz) / dt
            out.buttons.value[...] = self.status.buttons
            out.position.publish()
            out.velocity.publish()
            out.buttons.publish()
        self.last_read_ns = now
        self._frames(now)

    def _send(self, forces: bool) -> None:
        """The command frame: forces out when allowed (homed, position known), else zero."""
        if forces and self.homing.forces_allowed and self.fk_ok:
            self.kinematics.forces_to_motor(None, self.inputs.force.value, self.motor)  # zeros if it fails
        else:
            self.motor.fill(0)
        self.codec.encode_command(self.motor, self.homing.command_flags(), self.command)
        self.link.send(self.command)

    def _frames(self, now: int) -> None:
        """`frames_ok` falls 100 ms after the last good frame (the firmware's own force hold) and
        rises with the next one; each change is logged once. Without frames the position is not
        published, so its readers see it age past their streams' `max_age`."""
        ok = now - self.last_frame_ns < 100_000_000
        if ok != self.frames_ok:
            if ok and not self.framed:
                self.framed = True
                self.log.info("first good frame %.2f s after opening", (now - self.opened_ns) / 1e9)
            elif ok:
                self.log.info("frames are back")
            else:
                self.log.warning("no good frame for 100 ms: the Falcon holds no force, the robot is stopped")
            self.frames_ok = self.flags["frames_ok"] = ok
