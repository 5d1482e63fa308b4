"""The simulated Falcon and the blind operator as blocks: the Falcon's frames over the link, the
simulator's faults, and an operator who homes when the LED is red and drives when told."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np

from hapticop.devices.falcon import Flag, FrameCodec, Homing, Status, new_frame
from hapticop.devices.falcon.link import DatagramFalconLink
from hapticop.devices.link import DatagramLink
from hapticop.runtime.clock import VirtualClock
from hapticop.runtime.context import ActivityContext, InputPort, OutputPort
from hapticop.sim.blind_operator import Operator, OperatorParams
from hapticop.sim.devices.falcon import FalconSimulator, FalconSimulatorParams


def _block(cls, name, params, clock, run_dir, flags=None):
    inputs = SimpleNamespace(**{n: InputPort(n, p, clock.now_ns) for n, p in cls.inputs.items()})
    outputs = SimpleNamespace(**{n: OutputPort(n, p, clock.now_ns) for n, p in cls.outputs.items()})
    block = cls(ActivityContext(name, params, inputs, outputs, flags if flags is not None else {}, clock,
                                logging.getLogger(f"test.{name}"), np.random.default_rng(0), run_dir))
    block.create()
    block.configure_resources()
    return block


def _tick(clock):
    clock.advance_to(clock.now_ns() + 1_000_000)


def test_the_simulator_answers_each_command_frame_with_a_status_frame(tmp_path):
    clock = VirtualClock()
    device = _block(FalconSimulator, "falcon_sim", FalconSimulatorParams(), clock, tmp_path)
    host = DatagramFalconLink(DatagramLink.host(tmp_path, "falcon_sim", memory=clock.virtual))
    codec, homing, command, status = FrameCodec(), Homing(), new_frame(), Status()
    codec.encode_command((0, 0, 0), homing.command_flags(), command)
    _tick(clock)
    device.compute()
    assert not host.receive(status)  # nothing asked, nothing answered: the handle just rests
    host.send(command)
    _tick(clock)
    device.compute()
    assert host.receive(status) and not host.receive(status)  # one reply per command
    assert int(device.outputs.leds.value) == int(Flag.LED_RED)  # what the host lit: home me
    assert device.outputs.handle_position.published == 2
    host.close()
    device.clean()


def test_the_simulated_faults_silence_or_corrupt_the_replies(tmp_path):
    clock = VirtualClock()
    device = _block(FalconSimulator, "falcon_sim", FalconSimulatorParams(), clock, tmp_path)
    host = DatagramFalconLink(DatagramLink.host(tmp_path, "falcon_sim", memory=clock.virtual))
    command, status = new_frame(), Status()
    FrameCodec().encode_command((0, 0, 0), int(Flag.HOMING), command)
    for fault, answered in (("silent", False), ("corrupt", False), ("none", True)):
        device.params = device.context.params = FalconSimulatorParams(sim_fault=fault)  # a running parameter
        host.send(command)
        _tick(clock)
        device.compute()
        assert host.receive(status) is answered, fault
    assert host.rejected == 1  # the corrupted frame arrived and the codec refused it
    host.close()
    device.clean()


def test_the_operator_homes_while_the_led_is_red_rests_when_green_and_drives_when_told(tmp_path):
    clock, flags = VirtualClock(), {"operator_go": False}
    operator = _block(Operator, "operator", OperatorParams(), clock, tmp_path, flags)
    leds, hand = operator.inputs.leds.value, operator.outputs.hand_force.value

    def step(led: int) -> np.ndarray:
        leds[...] = led
        _tick(clock)
        operator.compute()
        return hand.copy()

    assert not step(0).any()  # nobody asked: hands resting on the grip
    assert step(int(Flag.LED_RED))[2] > 1.0  # home me: the grip is pulled out (+z) first
    assert not step(int(Flag.LED_GREEN)).any()  # homed: resting until told to drive
    assert operator.outputs.driving_time.published == 0
    flags["operator_go"] = True
    step(int(Flag.LED_GREEN))
    step(int(Flag.LED_GREEN))
    assert operator.outputs.driving_time.published == 2 and float(operator.outputs.driving_time.value) > 0.0
    assert step(int(Flag.LED_RED))[2] > 1.0  # the Falcon lost its homing: homed again, from the start


def test_the_falcon_says_nothing_of_lost_frames_before_its_first_one(tmp_path):
    """Opening the link is no frame: a simulator (or a Falcon) that answers only seconds later, as one in a
    process still starting does, leaves `frames_ok` false without a warning; its first frame raises it, and
    only frames that then stop for 100 ms are lost ones."""
    from hapticop.testing import BlockHarness

    falcon = BlockHarness("falcon", {"driver": "sim", "simulator": "falcon_sim"}, name="falcon", run_dir=tmp_path)
    falcon.block.create()
    falcon.block.configure_resources()
    for _ in range(500):  # half a second with nobody answering
        falcon.block.configure_capabilities()
        falcon.advance()
    assert not falcon.flags["frames_ok"]
    assert not any("warning" in line for line in falcon.log_lines())
    device = _block(FalconSimulator, "falcon_sim", FalconSimulatorParams(), falcon.clock, tmp_path)
    for _ in range(5):
        device.compute()
        falcon.block.configure_capabilities()
        falcon.advance()
    assert falcon.flags["frames_ok"]
    assert any("first good frame 0.50 s after opening" in line for line in falcon.log_lines())
    for _ in range(150):  # the simulator falls silent
        falcon.block.configure_capabilities()
        falcon.advance()
    assert not falcon.flags["frames_ok"]
    assert any("warning: no good frame for 100 ms" in line for line in falcon.log_lines())
    falcon.clean()
    device.clean()
