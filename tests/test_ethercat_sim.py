"""The EtherCAT master's sim driver: process-data images to the simulated ropod and back over
a datagram link, in the same compute/flush split as on a wire, and the plant's true motion."""

from __future__ import annotations

import numpy as np
import pytest

from hapticop.blocks.ethercat import EthercatMaster, EthercatMasterParams
from hapticop.devices.ropod.pdo import Com1, Stat1, rxpdo_view, txpdo_view
from hapticop.runtime.clock import VirtualClock
from hapticop.sim.devices.ropod_plant import RopodPlantSimulator

from .runtime_helpers import standalone

TORQUE = int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_TORQUE)


def _segment(tmp_path, slaves: int = 7):
    clock = VirtualClock()
    plant = standalone(RopodPlantSimulator, "ropod_plant", {"slaves": slaves}, tmp_path, clock)
    master = standalone(EthercatMaster, "ethercat", {"driver": "sim", "simulator": "ropod_plant"}, tmp_path, clock)
    for block in (plant, master):
        block.create()
        assert block.configure_resources() is not False

    def cycle() -> None:
        """One cycle of a thread scheduling [ropod_plant, ethercat, (the controller)]."""
        clock.advance_to(clock.now_ns() + 1_000_000)
        plant.compute()
        master.compute()
        master.flush()

    return plant, master, cycle


def test_the_ports_do_not_change_with_the_driver():
    sim = EthercatMaster.declare(EthercatMasterParams(driver="sim", simulator="ropod_plant"))
    real = EthercatMaster.declare(EthercatMasterParams(driver="pysoem"))
    assert (sim.inputs, sim.outputs) == (real.inputs, real.outputs)
    assert [need.activity for need in sim.needs] == ["ropod_plant"] and real.needs == ()


def test_a_sim_master_needs_its_simulator():
    with pytest.raises(ValueError, match="driver 'sim' needs 'simulator'"):
        EthercatMasterParams(driver="sim")


def test_commands_reach_the_plant_and_its_sensors_come_back_in_the_next_cycle(tmp_path):
    plant, master, cycle = _segment(tmp_path)
    out = master.outputs
    try:
        cycle()
        assert master.flags["operational"] and int(out.working_counter.value) == 12
        assert out.slave_states.value.tolist() == [8] * 7 and out.wheel_sensors.published == 1
        status = txpdo_view(out.wheel_sensors.value)["status1"]
        assert np.all(status & int(Stat1.ENCODERS_OK) == int(Stat1.ENCODERS_OK))

        commands = rxpdo_view(master.inputs.wheel_commands.value)  # what a controller writes
        commands["command1"], commands["setpoint1"], commands["setpoint2"] = TORQUE, 1.0, -1.0
        commands["limit1_p"], commands["limit1_n"], commands["limit2_p"], commands["limit2_n"] = 10, -10, 10, -10
        for _ in range(500):
            cycle()
        np.testing.assert_array_equal(plant.commands, master.inputs.wheel_commands.value)
        assert abs(plant.outputs.robot_pose.value[0]) > 0.01  # driven: the true pose moved from the start
        np.testing.assert_array_equal(plant.outputs.robot_pose.value, plant.plant.pose)
        assert out.wheel_sensors.published == 501 and plant.outputs.robot_pose.published == 501
    finally:
        master.clean()
        plant.clean()


def test_no_reply_is_nothing_new_and_not_operational(tmp_path):
    plant, master, cycle = _segment(tmp_path)
    try:
        cycle()
        master.compute()  # a cycle the plant did not answer
        assert not master.flags["operational"] and master.outputs.wheel_sensors.published == 1
    finally:
        master.clean()
        plant.clean()


def test_a_segment_of_other_slaves_is_refused_clearly(tmp_path):
    plant, master, cycle = _segment(tmp_path, slaves=5)
    try:
        with pytest.raises(ValueError, match="answered 681 bytes, the master expects 683"):
            cycle()
    finally:
        master.clean()
        plant.clean()


def test_a_slave_fault_is_held_long_enough_for_every_loop_to_see_it():
    """A wheel that drops out of OP for one cycle raises slave_fault for fault_hold_ms, so the ropod
    controller on its own thread holds the robot, and a flapping wheel does not jerk it back into motion."""
    from hapticop.testing import BlockHarness

    harness = BlockHarness("ethercat_watchdog", {"fault_hold_ms": 50.0}, name="watchdog")
    harness.configure()
    op, blip = np.full(7, 8, np.uint8), np.array([8, 8, 8, 0x14, 8, 8, 8], np.uint8)

    def cycle(states) -> bool:
        harness.feed("slave_states", states)
        harness.feed("working_counter", np.int32(12))
        harness.step()
        return bool(harness.flags["slave_fault"])

    assert not any(cycle(op) for _ in range(5))
    assert cycle(blip)  # one cycle out of OP
    held = [cycle(op) for _ in range(60)]
    assert held[:49] == [True] * 49 and held[-5:] == [False] * 5  # 50 ms at 1 kHz, then released
    assert harness.flags["all_operational"]  # the segment itself was healthy again at once
