"""The Novint Falcon haptic device: handle position in, motor forces out, at 1 kHz.

Geometry defaults to libnifalcon's values so its reference data applies
(../shared/reference/falcon-kinematics.md).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
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
    scene: str = Field("hallway", description="the simulated world whose operator holds the handle (sim driver)")
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

    # -- life cycle -------------------------------------------------------------------------
    def configure_resources(self) -> bool:
        from hapticop.devices.falcon import (
            WORKSPACE_CENTRE_M, FalconKinematics, FrameCodec, Geometry, Homing, SimulatedFalcon, Status, new_frame,
        )
        from hapticop.sim.scene import find_scene

        if self.params.driver == "usb":
            raise RuntimeError("the usb driver is not part of this hapticop yet; use driver: sim")
        self.scene = find_scene(self.params.scene)
        if self.scene is None:
            return False  # the world activity has not opened the simulated world yet
        geometry = Geometry(**self.params.geometry.model_dump())
        self.kinematics, self.codec, self.homing = FalconKinematics(geometry), FrameCodec(), Homing()
        self.status, self.command, self.reply = Status(), new_frame(), new_frame()
        self.centre = np.asarray(WORKSPACE_CENTRE_M, dtype=float)
        operator = self.scene.operator
        self.device = SimulatedFalcon(geometry, handle_mass_kg=0.1 + operator.mass_kg, rng=self.rng)
        self.position = np.zeros(3)  # device frame, workspace origin
        self.previous = np.zeros(3)
        self.motor = np.zeros(3, dtype=np.int64)
        self.hand = np.zeros(3)
        self.absolute = np.zeros(3)
        self.fk_ok = False
        self.last_frame_ns = self.started_ns = self.last_ns = self.clock.now_ns()
        self.homing_target = np.zeros(3)
        self.outputs.position.value[:] = 0.0
        return True

    def configure_capabilities(self) -> bool:
        """Homing: the hand pulls the grip out, then pushes it in (falcon-protocol.md §6)."""
        elapsed = (self.clock.now_ns() - self.started_ns) / 1e9
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
        scene = self.scene
        np.subtract(self.device.position, self.centre, out=scene.handle_position)
        np.copyto(scene.handle_velocity, self.device.velocity)
        np.copyto(scene.device_force, self.inputs.force.value)
        if scene.operator_since_ns is None:
            self.hand[:] = 0.0  # hands resting on the grip until told to drive
        else:
            scene.operator.step(scene.operator_time(self.clock.now_ns()), scene.environment_force,
                                scene.handle_position, self.hand, scene.handle_velocity)
        np.copyto(scene.hand_force, self.hand)
        self._exchange(self.hand, forces=True)

    def pausing(self) -> None:
        self.hand[:] = 0.0
        self._exchange(self.hand, forces=False)

    def clean(self) -> None:
        if hasattr(self, "device"):
            self.hand[:] = 0.0
            self._exchange(self.hand, forces=False)  # a last frame with zero forces
            self.flags["frames_ok"] = False

    def _exchange(self, hand_force: np.ndarray, forces: bool) -> None:
        """One frame each way: forces out (when allowed), encoders in, then kinematics."""
        now = self.clock.now_ns()
        dt = min(max(now - self.last_ns, 0), 5_000_000) / 1e9 or 1e-3
        self.last_ns = now
        self.motor[:] = 0
        if forces and self.homing.forces_allowed and self.fk_ok:
            self.kinematics.forces_to_motor(None, self.inputs.force.value, self.motor)
        self.codec.encode_command(self.motor, self.homing.command_flags(), self.command)
        if self.device.exchange(self.command, dt, hand_force, out=self.reply) is None:
            return
        try:
            self.codec.decode_status(self.reply, self.status)
        except Exception:  # noqa: BLE001 - a corrupted frame is dropped; frames_ok tells
            return
        self.last_frame_ns = now
        self.homing.update(self.status)
        if self.homing.just_homed:
            self.kinematics.reset()  # the counts just became absolute
        self.fk_ok = self.kinematics.forward(self.status.encoders, self.absolute)
        if self.fk_ok:
            np.copyto(self.previous, self.position)
            np.subtract(self.absolute, self.centre, out=self.position)
            out = self.outputs
            np.copyto(out.position.value, self.position)
            np.subtract(self.position, self.previous, out=out.velocity.value)
            out.velocity.value /= dt
            out.buttons.value[...] = self.status.buttons
            out.position.publish()
            out.velocity.publish()
            out.buttons.publish()
        self.flags["frames_ok"] = now - self.last_frame_ns < 100_000_000
