"""The Novint Falcon haptic device: handle position in, motor forces out, at 1 kHz.

Geometry defaults to libnifalcon's values so its reference data applies
(../shared/reference/falcon-kinematics.md). `driver: sim` exchanges frames with a simulated
handle held by the scene's operator; `driver: usb` runs the USB driver (`usb_driver`) on a
real Falcon, or with `usb_backend: virtual` on the virtual Falcon of `virtual_usb`, whose
simulated hand does the homing motion and then lets go.
"""

from __future__ import annotations

import threading
import time
from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator
from pydantic_core import PydanticCustomError

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
    scene: str = Field("hallway", description="the simulated world whose operator holds the handle (sim driver)")
    device_index: int = Field(0, ge=0, description="which Falcon, when several are on USB")
    firmware: str | None = Field(None, description="path to Novint's firmware image (usb driver); never shipped")
    firmware_sha256: str | None = Field(
        None, description="accept this image instead of Novint's known ones (usb driver): you vouch for it")
    usb_backend: Literal["libusb", "virtual"] = Field(
        "libusb", description="usb driver: 'libusb' for a real Falcon, 'virtual' for the simulated USB device")
    homing: bool = Field(True, description="home the encoders in capability configuration")
    geometry: FalconGeometry = Field(default_factory=FalconGeometry)
    sim_fault: Literal["none", "silent", "corrupt"] = Field(
        "none", description="sim driver: a fault of the simulated link, for fault scenarios (set it by a patch): "
        "'silent' the device stops answering, 'corrupt' every status frame arrives with a byte flipped")

    @field_validator("firmware_sha256")
    @classmethod
    def _is_sha256(cls, value: str | None) -> str | None:
        if value is not None and (len(value) != 64 or any(c not in "0123456789abcdefABCDEF" for c in value)):
            raise PydanticCustomError("sha256", "'firmware_sha256' must be a SHA-256 digest: 64 hex digits")
        return value

    @model_validator(mode="after")
    def _usb_needs_firmware(self) -> "FalconParams":
        if self.driver == "usb" and not self.firmware:
            raise PydanticCustomError(
                "usb_firmware", "driver 'usb' needs 'firmware': the path to Novint's Falcon firmware image "
                "(nvent_firmware.bin, from Novint's installer or a libnifalcon checkout; hapticop never ships it)")
        return self


class _DeviceClock:
    """The runtime's clock as the virtual USB device wants it (seconds; sleeps only in real time)."""

    def __init__(self, clock) -> None:
        self._clock = clock

    def now(self) -> float:
        return self._clock.now_ns() / 1e9

    def sleep(self, seconds: float) -> None:
        if seconds > 0 and not getattr(self._clock, "virtual", False):
            time.sleep(seconds)


class Falcon(Block):
    Params = FalconParams
    inputs = {"force": Port("float64", (3,), "N", "force to render at the handle, device frame")}
    outputs = {
        "position": Port("float64", (3,), "m", "handle position, device frame, origin at the workspace centre"),
        "velocity": Port("float64", (3,), "m/s", "handle velocity, differentiated from position"),
        "buttons": Port("uint8", (), "1", "button bit mask"),
    }
    running_params = frozenset({"sim_fault"})
    flags_written = {"frames_ok": "frames arrive and decode (false after 100 ms without one)"}
    rate = RateRange(900.0, 1100.0, "the Falcon firmware exchanges frames at about 1 kHz and holds a force only 100 ms")

    # -- life cycle -------------------------------------------------------------------------
    def configure_resources(self) -> bool:
        from hapticop.devices.falcon import (
            WORKSPACE_CENTRE_M, FalconKinematics, FrameCodec, Geometry, Homing, SimulatedFalcon, Status, new_frame,
        )
        from hapticop.sim.scene import find_scene

        geometry = Geometry(**self.params.geometry.model_dump())
        self.usb = None
        if self.params.driver == "usb":
            if not self._usb_connected(geometry):
                return False  # opening, and maybe loading firmware, on a helper thread
        else:
            self.scene = find_scene(self.params.scene)
            if self.scene is None:
                return False  # the world activity has not opened the simulated world yet
        self.kinematics, self.codec, self.homing = FalconKinematics(geometry), FrameCodec(), Homing()
        self.status, self.command, self.reply = Status(), new_frame(), new_frame()
        self.centre = np.asarray(WORKSPACE_CENTRE_M, dtype=float)
        self.centre_xyz = tuple(WORKSPACE_CENTRE_M)
        if self.usb is None:
            self.device = SimulatedFalcon(geometry, handle_mass_kg=0.1 + self.scene.operator.mass_kg, rng=self.rng)
        self.position = (0.0, 0.0, 0.0)  # device frame, workspace origin: last published, as floats
        self.motor = np.zeros(3, dtype=np.int64)
        self.hand = np.zeros(3)
        self.absolute = np.zeros(3)
        self.fk_ok = False
        self.last_frame_ns = self.started_ns = self.last_ns = self.last_read_ns = self.clock.now_ns()
        self.replied = False  # the simulated device's reply to the last command waits in `reply`
        self.frames_ok = False
        self.homing_target = np.zeros(3)
        self.outputs.position.value[:] = 0.0
        return True

    def _usb_connected(self, geometry) -> bool:
        """Open the Falcon (loading its firmware if needed) without blocking the thread's cycles.

        The firmware file is checked first, here, so a wrong file fails at once and clearly.
        """
        from hapticop.devices.falcon import Homing
        from hapticop.devices.falcon.firmware import read_firmware
        from hapticop.devices.falcon.usb_driver import FalconUsbError, connect, system_backend

        self._usb_error = FalconUsbError
        if getattr(self, "_connecting", None) is None:
            p = self.params
            image = read_firmware(p.firmware, p.firmware_sha256)
            backend = system_backend() if p.usb_backend == "libusb" else self._virtual_backend(geometry)
            self._connection: dict = {"log": []}

            def run() -> None:
                try:
                    self._connection["falcon"] = connect(image, p.device_index, backend,
                                                         log=self._connection["log"].append)
                except BaseException as error:  # noqa: BLE001 - handed to the life cycle below
                    self._connection["error"] = error

            self._connecting = threading.Thread(target=run, name=f"{self.name}-usb-open", daemon=True)
            self._connecting.start()
        if self._connecting.is_alive():
            return False
        self._connecting = None
        for line in self._connection["log"]:
            self.log.info("%s", line)
        if "error" in self._connection:
            raise self._connection["error"]
        self.usb = self._connection["falcon"]
        self.log.info("Falcon open on USB; %s", Homing.INSTRUCTIONS)
        return True

    def _virtual_backend(self, geometry):
        from hapticop.devices.falcon import SimulatedFalcon
        from hapticop.devices.falcon.virtual_usb import HomingHand, VirtualFalcon, VirtualUsbBackend

        falcon = SimulatedFalcon(geometry, rng=self.rng)
        self.virtual = VirtualFalcon(_DeviceClock(self.clock), falcon=falcon, hand=HomingHand())
        return VirtualUsbBackend(self.virtual)

    def configure_capabilities(self) -> bool:
        """Homing: the hand pulls the grip out, then pushes it in (falcon-protocol.md §6)."""
        elapsed = (self.clock.now_ns() - self.started_ns) / 1e9
        if self.usb is not None:  # a person (or the virtual device's hand) does the moving
            self._exchange(self.hand, forces=False)
            if self.homing.homed:
                self.log.info("homed after %.2f s", elapsed)
            return self.homing.homed
        self.homing_target[2] = 0.178 if elapsed % 2.5 < 0.8 else 0.075
        np.subtract(self.homing_target, self.device.position, out=self.hand)
        self.hand *= 300.0
        self.hand -= 20.0 * self.device.velocity
        self._exchange(self.hand, forces=False)
        if self.homing.homed:
            self.log.info("homed after %.2f s", elapsed)
            self.scene.operator.reset()
            return True
        return False

    def compute(self) -> None:
        """Read: the status frame answering the last command (and, simulated, the operator's
        hand). The force goes out in `flush`, once the haptic controller has computed it from
        this reading."""
        if self.usb is None:
            scene = self.scene
            self.device.copy_state(scene.handle_position, scene.handle_velocity)
            np.subtract(scene.handle_position, self.centre, out=scene.handle_position)
            np.copyto(scene.device_force, self.inputs.force.value)
            if scene.operator_since_ns is None:
                self.hand.fill(0.0)  # hands resting on the grip until told to drive
            else:
                with self.context.simulation:
                    scene.operator.step(scene.operator_time(self.clock.now_ns()), scene.environment_force,
                                        scene.handle_position, self.hand, scene.handle_velocity)
            np.copyto(scene.hand_force, self.hand)
        self._receive()

    def flush(self) -> None:
        """Write: the command frame with the force this cycle computed."""
        self._send(self.hand, forces=True)

    def pausing(self) -> None:
        self.hand[:] = 0.0
        self._exchange(self.hand, forces=False)

    def clean(self) -> None:
        if hasattr(self, "device") or getattr(self, "usb", None) is not None:
            self.hand[:] = 0.0
            self._exchange(self.hand, forces=False)  # a last frame with zero forces
            self.frames_ok = self.flags["frames_ok"] = False
        connecting = getattr(self, "_connecting", None)
        if connecting is not None:  # cleaned while still opening: wait for it, then let go
            connecting.join(30.0)
            self._connecting = None
            self.usb = self._connection.get("falcon")
        if getattr(self, "usb", None) is not None:
            self.usb.close()
            self.usb = None

    def _exchange(self, hand_force: np.ndarray, forces: bool) -> None:
        """Both halves of a cycle at once, outside running (homing, pausing, the last frame)."""
        self._receive()
        self._send(hand_force, forces)

    def _receive(self) -> None:
        """The status frame answering the last command: encoders in, then kinematics."""
        now = self.clock.now_ns()
        if not self._received():
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

    def _send(self, hand_force: np.ndarray, forces: bool) -> None:
        """The command frame: forces out when allowed (homed, position known), else zero."""
        now = self.clock.now_ns()
        dt = min(max(now - self.last_ns, 0), 5_000_000) / 1e9 or 1e-3
        self.last_ns = now
        if forces and self.homing.forces_allowed and self.fk_ok:
            self.kinematics.forces_to_motor(None, self.inputs.force.value, self.motor)  # zeros if it fails
        else:
            self.motor.fill(0)
        self.codec.encode_command(self.motor, self.homing.command_flags(), self.command)
        if self.usb is not None:
            try:
                self.usb.send(self.command)
            except self._usb_error as error:
                self._usb_lost(error)
            return
        with self.context.simulation:
            self.replied = self.device.exchange(self.command, dt, hand_force, out=self.reply) is not None

    def _frames(self, now: int) -> None:
        """`frames_ok` falls 100 ms after the last good frame (the firmware's own force hold) and
        rises with the next one; each change is logged once. Without frames the position is not
        published, so its readers see it age past their streams' `max_age`."""
        ok = now - self.last_frame_ns < 100_000_000
        if ok != self.frames_ok:
            if ok:
                self.log.info("frames are back")
            else:
                self.log.warning("no good frame for 100 ms: the Falcon holds no force, the robot is stopped")
            self.frames_ok = self.flags["frames_ok"] = ok

    def _received(self) -> bool:
        """True when `self.status` holds a new status frame: the reply to the last command."""
        if self.usb is not None:
            try:
                return self.usb.receive(self.status)
            except self._usb_error as error:
                self._usb_lost(error)
                return False
        if not self.replied:
            return False
        self.replied = False
        fault = self.params.sim_fault
        if fault == "silent":
            return False  # the device moved on, but its reply never arrived
        if fault == "corrupt":
            self.reply[7] ^= 0x5A  # a flipped byte on the wire: the codec must refuse the frame
        try:
            self.codec.decode_status(self.reply, self.status)
        except Exception:  # noqa: BLE001 - a corrupted frame is dropped; frames_ok tells
            return False
        return True

    def _usb_lost(self, error: Exception) -> None:
        """Unplugged, powered off: frames stop and frames_ok tells; the error is logged once."""
        if not getattr(self, "_usb_failed", False):
            self._usb_failed = True
            self.log.error("%s", error)
