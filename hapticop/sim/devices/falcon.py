"""The simulated Falcon as an activity: it answers the Falcon block's frames, with a hand on its grip.

It is the device end of the Falcon block's link (`driver: sim`, `simulator: <this activity>`):
each cycle it takes the command frames that arrived, steps the handle's physics one period under
the motors' force and the operator's hand (an input stream), and answers every valid command with
one status frame through the real codec, as the firmware does. The true handle state goes out as
streams for the operator and the world, with the LEDs the host lights (red: home me, green: homed),
which is what a person holding the grip can see; the buttons the operator holds go out in every status
frame. Placed just before the Falcon block in one thread's schedule it keeps the block's timing
exactly (the command sent in the block's `flush` is answered before the block's next `compute`); on
a thread or process of its own it answers a cycle or so later, as a device on a wire would.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port
from hapticop.devices.falcon import WORKSPACE_CENTRE_M, Flag, SimulatedFalcon, new_frame
from hapticop.devices.falcon.mechanism import Geometry
from hapticop.devices.link import DatagramLink


class FalconSimulatorParams(Params):
    geometry: Geometry = Field(default_factory=Geometry, description="the simulated mechanism's dimensions")
    handle_mass_kg: float = Field(0.1, gt=0, description="the handle's own moving mass")
    hand_mass_kg: float = Field(0.5, ge=0, description="the operator's hand, moving with the handle, while no "
                                "hand_mass stream says what grips it (the nominal operator's)")
    sim_fault: Literal["none", "silent", "corrupt"] = Field(
        "none", description="a fault of the simulated link, for fault scenarios (set it by a patch): "
        "'silent' the device stops answering, 'corrupt' every status frame leaves with a byte flipped")


class FalconSimulator(Block):
    Params = FalconSimulatorParams
    simulator = True
    provides = frozenset({"falcon_device"})
    running_params = frozenset({"sim_fault"})
    inputs = {
        "hand_force": Port("float64", (3,), "N", "the operator's hand on the grip, device frame", required=False),
        "buttons": Port("uint8", (), "1", "the grip buttons the operator holds (bit mask, codec Button bits)",
                        required=False),
        "hand_mass": Port("float64", (), "kg", "the mass of the hand on the grip now (0: let go); without it the "
                          "hand_mass_kg parameter's hand never lets go", required=False),
    }
    outputs = {
        "handle_position": Port("float64", (3,), "m", "true handle position, device frame, from the workspace centre"),
        "handle_velocity": Port("float64", (3,), "m/s", "true handle velocity, device frame"),
        "leds": Port("uint8", (), "1", "the LEDs the last command lit (codec Flag bits: red, green, blue)"),
    }

    def create(self) -> None:
        self.centre = np.asarray(WORKSPACE_CENTRE_M, dtype=float)
        self.led_bits = int(Flag.LED_RED | Flag.LED_GREEN | Flag.LED_BLUE)
        self.command, self.reply = new_frame(), new_frame()
        self.device: SimulatedFalcon | None = None  # from resource configuration on
        self.link: DatagramLink | None = None  # the device end of the Falcon's link
        self.last_ns = 0

    def configure_resources(self) -> None:
        """A Falcon powered on, answering on its link (again, with a patch's new parameters)."""
        p = self.params
        if self.link is not None:
            self.link.close()
        self.device = SimulatedFalcon(p.geometry, handle_mass_kg=p.handle_mass_kg + p.hand_mass_kg, rng=self.rng)
        self.link = DatagramLink.device(self.run_dir, self.name, memory=self.clock.virtual)
        self.last_ns = self.clock.now_ns()

    def compute(self) -> None:
        now = self.clock.now_ns()
        dt, self.last_ns = (now - self.last_ns) / 1e9, now
        hand, device, frame_size = self.inputs.hand_force.value, self.device, len(self.command)
        device.buttons = int(self.inputs.buttons.value)
        hand_mass = self.inputs.hand_mass
        if hand_mass.valid:  # the operator model leaves its mass to the device: it moves with the handle
            device.mass = self.params.handle_mass_kg + float(hand_mass.value)
        stepped = False
        while n := self.link.receive_into(self.command):
            if n != frame_size:
                continue  # no frame: the firmware would not answer it
            # the first command of the cycle moves the handle the whole period; later ones apply at once
            reply = device.exchange(self.command, 0.0 if stepped else dt, hand, out=self.reply)
            stepped = True
            if reply is not None:
                self._answer()
        if not stepped:
            device.step(dt, hand)  # no command: the last one holds, then drops (100 ms)
        out = self.outputs
        position = out.handle_position.value
        device.copy_state(position, out.handle_velocity.value)
        np.subtract(position, self.centre, out=position)
        out.leds.value[...] = device.flags & self.led_bits
        out.handle_position.publish()
        out.handle_velocity.publish()
        out.leds.publish()

    def _answer(self) -> None:
        fault = self.params.sim_fault
        if fault == "silent":
            return  # the device moved on, but its reply never leaves
        if fault == "corrupt":
            self.reply[7] ^= 0x5A  # a flipped byte on the wire: the host's codec must refuse the frame
        self.link.send(self.reply)

    def clean(self) -> None:
        if self.link is not None:
            self.link.close()
            self.link = None
