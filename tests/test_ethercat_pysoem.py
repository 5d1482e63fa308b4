"""The pysoem master against the emulated ropod segment, over a veth pair in a private namespace.

Unmodified pysoem sends real EtherCAT frames; the emulator (its own process) answers them.
Needs root for the namespace and raw sockets: without the rights these tests skip, saying so.
"""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from hapticop.devices.ethercat.emulator.sandbox import Sandbox, namespace_problem

PROBLEM = namespace_problem()
pytestmark = pytest.mark.skipif(PROBLEM is not None, reason=f"EtherCAT over veth: {PROBLEM}")

from hapticop.blocks.ethercat import SMARTWHEEL_LAYOUT  # noqa: E402
from hapticop.devices.ethercat.emulator.ropod_segment import EK1100, EK1122, SWMC  # noqa: E402
from hapticop.devices.ethercat.master import BringUpError, ExpectedSlave, SoemMaster  # noqa: E402
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES, Com1, new_rx_image, rxpdo_view  # noqa: E402

NAMES = ["ek1100", "ek1122_front", "wheel_1", "wheel_2", "ek1122_rear", "wheel_3", "wheel_4"]
PRODUCTS = [EK1100, EK1122, SWMC, SWMC, EK1122, SWMC, SWMC]
WHEELS = [2, 3, 5, 6]
# The emulator is a Python process sharing the cores: on a busy machine its answers (a frame, a
# CoE mailbox reply) can take far longer than a wire's, so the master waits generously here.
TIMEOUTS = dict(receive_timeout_us=20_000, frame_timeout_us=10_000, mailbox_timeout_us=5_000_000)


def expected(products=PRODUCTS, names=NAMES):
    return [ExpectedSlave(n, p, *SMARTWHEEL_LAYOUT) if p == SWMC else ExpectedSlave(n, p)
            for n, p in zip(names, products)]


def _interface_here(name: str) -> bool:
    """Whether this thread's network namespace has the interface (sysfs would show the mount's)."""
    import socket

    try:
        socket.if_nametoindex(name)
        return True
    except OSError:
        return False


@pytest.fixture
def box():
    with Sandbox() as sandbox:
        yield sandbox


@pytest.fixture
def master(box):
    m = SoemMaster(box.interface, expected(), **TIMEOUTS)
    m.open()
    try:
        yield m
    finally:
        m.close()


def test_bring_up_reaches_op_with_the_expected_slaves(box, master):
    master.bring_up()
    assert [s.name for s in master.slaves] == ["EK1100", "EK1122", "SWMC", "SWMC", "EK1122", "SWMC", "SWMC"]
    assert [s.id for s in master.slaves] == PRODUCTS
    assert master.expected_wkc == 12  # 4 wheels x (2 for the outputs + 1 for the inputs)
    assert master.exchange() == 12
    status = box.fault("status")["slaves"]
    assert [s["state"] for s in status] == [8] * 7
    assert [s["station"] for s in status] == [0x1001 + i for i in range(7)]  # SOEM's station addresses


def test_a_wrong_slave_count_is_refused_by_name(box):
    m = SoemMaster(box.interface, expected(PRODUCTS[:6], NAMES[:6]), **TIMEOUTS)
    m.open()
    try:
        with pytest.raises(BringUpError, match=r"found 7 slaves on 'hapticop-ecat0', expected 6"):
            m.bring_up()
    finally:
        m.close()


def test_a_wrong_product_code_is_refused_by_position_and_code(box):
    products = list(PRODUCTS)
    products[5] = 0x01701001  # the older SmartWheel2 prototype
    m = SoemMaster(box.interface, expected(products), **TIMEOUTS)
    m.open()
    try:
        with pytest.raises(BringUpError, match=r"slave 5 is SWMC with product code 0x01705011; "
                                               r"expected wheel_3 with product code 0x01701001"):
            m.bring_up()
    finally:
        m.close()


def test_an_empty_wire_and_a_missing_interface_are_clear_errors():
    with Sandbox(emulator=False) as empty:
        m = SoemMaster(empty.interface, expected(), **TIMEOUTS)
        m.open()
        try:
            with pytest.raises(BringUpError, match="no EtherCAT slave answers on 'hapticop-ecat0'"):
                m.bring_up()
        finally:
            m.close()
        with pytest.raises(BringUpError, match="cannot open EtherCAT interface 'nosuch0'"):
            SoemMaster("nosuch0", expected()).open()


def test_process_data_round_trip_is_bit_exact(box, master):
    master.bring_up()
    box.fault("physics", run=False)  # the robot holds still: its sensor images stay put
    rng = np.random.default_rng(7)
    outputs = rng.integers(0, 256, (4, RXPDO_BYTES), dtype=np.uint8)
    for wheel, position in enumerate(WHEELS):
        master.write_outputs(position, outputs[wheel])
    assert master.exchange() == 12
    status = box.fault("status")
    assert [bytes.fromhex(h) for h in status["outputs"]] == [row.tobytes() for row in outputs]
    inputs = np.zeros((4, TXPDO_BYTES), np.uint8)
    for wheel, position in enumerate(WHEELS):
        master.read_inputs(position, inputs[wheel])
    assert [bytes.fromhex(h) for h in status["inputs"]] == [row.tobytes() for row in inputs]
    assert len(set(status["inputs"])) == 4 and inputs.any()  # four real, different sensor images


def test_outputs_of_the_wrong_length_are_refused_before_pysoem_copies_them(master):
    master.bring_up()
    with pytest.raises(ValueError, match="outputs of wheel_1 are 36 bytes, got 37"):
        master.write_outputs(2, np.zeros(37, np.uint8))


def test_fault_requests_that_make_no_sense_are_refused_and_the_segment_runs_on(box, master):
    master.bring_up()
    for op, args in (("cut", {"slave": 7}), ("reconnect", {"slave": 5}), ("restore", {"slave": 2}),
                     ("lose", {"slave": "2"}), ("cut", {"slave": None}), ("unplug", {"slave": 2})):
        with pytest.raises(RuntimeError, match=f"emulator refused {op}: "):
            box.fault(op, **args)
    assert master.exchange() == 12
    assert all(s["reached"] and s["state"] == 8 for s in box.fault("status")["slaves"])


def _pass_safe_op_error(master, positions) -> None:
    """What SOEM's check does for a slave in SAFE-OP+ERROR: acknowledge (SAFE-OP + 0x10)."""
    for p in positions:
        master.slaves[p].state = 0x04 | 0x10
        master.slaves[p].write_state()


def test_after_a_watchdog_trip_the_next_outputs_rearm_it_and_every_wheel_drives_again(box, master):
    """Read back through SOEM's own register access: 0x0440 falls to 0 when the outputs stop,
    and the first outputs after the acknowledgement set it to 1 again; back in OP, the drives run."""
    master.bring_up()
    rx = new_rx_image(4)
    view = rxpdo_view(rx)
    view["command1"] = int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_VELOCITY)
    view["limit1_p"] = view["limit2_p"] = 5.0
    view["limit1_n"] = view["limit2_n"] = -5.0
    for wheel, position in enumerate(WHEELS):
        master.write_outputs(position, rx[wheel])
    for _ in range(10):
        assert master.exchange() == 12
    assert [master.slaves[p]._fprd(0x0440, 2) for p in WHEELS] == [b"\x01\x00"] * 4
    # no outputs for longer than the watchdog time SOEM left programmed (the SII's 100 ms)
    _until(lambda: all(box.fault("status")["slaves"][p]["al_status"] == 0x14 for p in WHEELS),
           "every wheel trips its watchdog")
    master.master.read_state()
    assert [(master.slaves[p].state, master.slaves[p].al_status) for p in WHEELS] == [(0x14, 0x001B)] * 4
    assert [master.slaves[p]._fprd(0x0440, 2) for p in WHEELS] == [b"\x00\x00"] * 4
    _pass_safe_op_error(master, WHEELS)
    master.exchange()
    assert [master.slaves[p]._fprd(0x0440, 2) for p in WHEELS] == [b"\x01\x00"] * 4  # re-armed
    master.master.state = 0x08
    master.master.write_state()
    for _ in range(10):
        master.exchange()
    assert master.master.state_check(0x08, 50_000) == 0x08
    for _ in range(10):
        master.exchange()
    assert all(_drives(w) for w in box.fault("status")["wheels"])


def test_a_request_for_init_is_honoured_from_safe_op_with_the_error(box, master):
    master.bring_up()
    master.exchange()
    box.fault("trip_watchdog", slave=3)
    master.master.read_state()
    wheel = master.slaves[3]
    assert (wheel.state, wheel.al_status) == (0x14, 0x001B)
    wheel.state = 0x01  # INIT, with no acknowledgement: SOES and ESCs go, and the error is gone
    wheel.write_state()
    assert wheel.state_check(0x01, 50_000) == 0x01
    master.master.read_state()
    assert (wheel.state, wheel.al_status) == (0x01, 0)


def test_close_takes_every_slave_back_to_init_and_the_sandbox_leaves_nothing(box):
    home = os.readlink("/proc/thread-self/ns/net")
    with Sandbox(interface="hapticop-ecat7", peer="hapticop-esc7") as inner:
        assert os.readlink("/proc/thread-self/ns/net") != home
        m = SoemMaster(inner.interface, expected(), **TIMEOUTS)
        m.open()
        m.bring_up()
        m.close()
        assert [s["state"] for s in inner.fault("status")["slaves"]] == [1] * 7
        process = inner.process
        assert _interface_here("hapticop-ecat7")
    assert process.poll() is not None  # the emulator is gone
    assert not _interface_here("hapticop-ecat7") and not _interface_here("hapticop-esc7")
    assert os.readlink("/proc/thread-self/ns/net") == home


# --- CoE and distributed clocks, as SOEM's own tools use them --------------------------------

def _register(slave, address: int, size: int) -> int:
    return int.from_bytes(slave._fprd(address, size), "little")


def test_sdo_reads_give_the_wheels_identity_and_pdo_assignment(master):
    import pysoem

    master.master.config_init()
    master.master.state_check(2, 50_000)
    for position, slave in enumerate(master.master.slaves):
        if position not in WHEELS:
            continue
        assert int.from_bytes(slave.sdo_read(0x1018, 2), "little") == SWMC
        assert slave.sdo_read(0x1018, 0) == b"\x04"
        assert int.from_bytes(slave.sdo_read(0x1C12, 1), "little") == 0x1600
        assert int.from_bytes(slave.sdo_read(0x1C13, 1), "little") == 0x1A00
        assert slave.sdo_read(0x100A, 0) == b"hapticop emulator"  # a normal (not expedited) upload
    wheel = master.master.slaves[WHEELS[0]]
    with pytest.raises(pysoem.SdoError) as aborted:
        wheel.sdo_read(0x2000, 0)
    assert aborted.value.abort_code == 0x06020000
    wheel.sdo_write(0x1C12, 0, b"\x00")  # writable in PRE-OP
    assert wheel.sdo_read(0x1C12, 0) == b"\x00"
    wheel.sdo_write(0x1C12, 0, b"\x01")
    with pytest.raises(pysoem.SdoError) as aborted:
        wheel.sdo_write(0x1C12, 1, b"\x01\x16\x00\x00")
    assert aborted.value.abort_code == 0x06070012  # four bytes for an UNSIGNED16


def test_soem_recovers_a_mailbox_answer_whose_reply_frame_was_lost(box, master):
    master.master.config_init()
    master.master.state_check(2, 50_000)
    wheel = master.master.slaves[WHEELS[1]]
    box.fault("lose_mailbox_reply", slave=WHEELS[1], frames=1)
    assert int.from_bytes(wheel.sdo_read(0x1018, 2), "little") == SWMC  # asked again with the repeat request
    assert box.fault("status")["ok"]


def test_bring_up_maps_every_entry_when_pdo_assignment_replies_are_lost(box):
    """SOEM reads the PDO assignment entry by entry; an entry whose answer is lost would shrink
    the mapping (an input 4 bytes short) unless the slave repeats it."""
    for wheel in WHEELS:
        box.fault("lose_mailbox_reply", slave=wheel, frames=6)
    m = SoemMaster(box.interface, expected(), **TIMEOUTS)
    m.open()
    try:
        m.bring_up()
        assert [len(m.slaves[w].input) for w in WHEELS] == [TXPDO_BYTES] * 4
    finally:
        m.close()


def _exchange_and_check(master, check, seconds: float) -> bool:
    """Exchange and check, as the fieldbus and watchdog threads do, for a while; True when every slave is in OP."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        master.exchange()
        if check.needed():
            check.check()
        time.sleep(0.001)
    return not check.pending


def test_late_state_reads_are_not_a_lost_segment_but_a_silent_one_is(box, master):
    """One datagram reads every slave's state: late frames leave them all reading NONE at once. That is
    read again, not taken for every slave lost; a segment that stays silent (its coupler loses power) is."""
    from hapticop.devices.ethercat.recovery import SlaveCheck

    master.bring_up()
    lines: list[str] = []
    check = SlaveCheck(master, lines.append, silent_ms=500.0)
    assert _exchange_and_check(master, check, 0.05) and check.check(), lines
    box.fault("late", delay_us=80_000, frames=3)  # the emulator answers nothing for about a quarter second
    _until(lambda: _exchange_and_check(master, check, 0.01), "every slave back in OP after the late frames")
    assert not [line for line in lines if "-> NONE" in line or "lost" in line], lines
    assert lines, "the late frames tripped the wheels' watchdogs, which the check acknowledged"
    box.fault("lose", slave=0)  # the coupler, and every slave behind it
    _until(lambda: _exchange_and_check(master, check, 0.01) or "wheel_4: lost" in lines, "the silent segment believed")
    assert all(f"{name}: lost" in lines for name in NAMES), lines


def test_config_dc_finds_the_wheels_clocks_and_dc_sync_starts_sync0(master):
    master.master.config_init()
    assert master.master.config_dc()
    slaves = master.master.slaves
    assert [bool(_register(s, 0x0008, 2) & 0x04) for s in slaves] == [p == SWMC for p in PRODUCTS]
    offsets = [_register(slaves[p], 0x0920, 8) for p in WHEELS]
    assert all(o > 0 for o in offsets)  # system time since 2000, from the master's clock
    wheel = slaves[WHEELS[0]]
    wheel.dc_sync(True, 2_000_000)
    assert (_register(wheel, 0x0980, 1), _register(wheel, 0x0981, 1)) == (0, 0x03)
    assert _register(wheel, 0x09A0, 4) == 2_000_000
    assert _register(wheel, 0x0990, 8) > _register(wheel, 0x0910, 8)  # the first pulse is ahead
    assert _register(wheel, 0x0984, 1) == 0x01  # pending, not refused as past


def test_the_bring_up_runs_sync0_at_the_cycle_and_the_dc_frame_keeps_the_working_counter(box):
    m = SoemMaster(box.interface, expected(), **TIMEOUTS, cycle_ns=2_000_000)
    m.open()
    try:
        m.bring_up()
        assert m.distributed_clocks and m.coe_checked == m.sync0 == ["wheel_1", "wheel_2", "wheel_3", "wheel_4"]
        for position in WHEELS:
            assert _register(m.slaves[position], 0x0981, 1) == 0x03
            assert _register(m.slaves[position], 0x09A0, 4) == 2_000_000
        assert m.exchange() == 12  # the LRW's count: SOEM reads the appended FRMW apart
        first = m.master.dc_time
        assert m.exchange() == 12
        assert m.master.dc_time > first > 0  # the reference wheel's system time came back in the FRMW
    finally:
        m.close()


def test_without_sync0_the_wheels_refuse_safe_op_with_0x0030(box):
    specs = [ExpectedSlave(n, p, RXPDO_BYTES, TXPDO_BYTES) if p == SWMC else ExpectedSlave(n, p)
             for n, p in zip(NAMES, PRODUCTS)]
    m = SoemMaster(box.interface, specs, **TIMEOUTS)
    m.open()
    try:
        with pytest.raises(BringUpError, match=r"wheel_1 PRE-OP\+ERR \(AL code 0x0030 Invalid DC SYNC config"):
            m.bring_up()
    finally:
        m.close()


def test_a_pdo_assignment_other_than_the_drivers_fails_bring_up_in_one_message(box):
    specs = [ExpectedSlave(n, p, RXPDO_BYTES, 172, sync0=True) if p == SWMC else ExpectedSlave(n, p)
             for n, p in zip(NAMES, PRODUCTS)]  # a KELO drive's 172-byte sensors
    m = SoemMaster(box.interface, specs, **TIMEOUTS)
    m.open()
    try:
        with pytest.raises(BringUpError, match=r"^slave wheel_1 \(SWMC\) assigns over CoE outputs 0x1600 \(9 entries, "
                                               r"36 bytes\) and inputs 0x1A00 \(40 entries, 168 bytes\); the driver "
                                               r"expects 36 output bytes and 172 input bytes$"):
            m.bring_up()
        assert [s["state"] for s in box.fault("status")["slaves"]] == [2] * 7  # stopped before mapping
    finally:
        m.close()


# --- the watchdog's recovery, with the runtime --------------------------------------------
# The real haptic controller commands the robot, as in systems/hallway.yaml; only its devices are
# stood in for: a hand holding the Falcon's handle pushed forward (0.3 m/s) and a LIDAR in open space.

RECOVERY = """
version: 1
name: ecat_recovery
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, hand, scan, haptic, watch]}}
  fieldbus: {period: 1ms, deploy: thread, schedules: {0: [ethercat, ropod]}}
  watchdog: {period: 1ms, deploy: thread, schedules: {0: [ethercat_watchdog]}}
activities:
  mediator: {block: mediator}
  hand: {block: "tests.blocks:HeldHandle", params: {push_m: [0.0, 0.0, -0.0157]}}
  scan: {block: "tests.blocks:OpenScan"}
  haptic: {block: haptic_controller}
  watch: {block: "tests.blocks:SetpointWatch"}
  ethercat: {block: ethercat_master, params: {driver: pysoem, interface: hapticop-ecat0, receive_timeout_us: 5000}}
  ropod: {block: ropod_controller}
  ethercat_watchdog: {block: ethercat_watchdog, params: {interface: hapticop-ecat0}}
streams:
  handle_position: {from: hand.position, to: haptic.handle_position}
  handle_velocity: {from: hand.velocity, to: haptic.handle_velocity}
  scan_ranges: {from: scan.ranges, to: haptic.ranges}
  scan_angles: {from: scan.angles, to: haptic.angles}
  velocity_setpoint: {from: haptic.velocity_setpoint, to: [ropod.velocity_setpoint, watch.velocity_setpoint]}
  platform_velocity: {from: ropod.platform_velocity, to: haptic.platform_velocity}
  wheel_sensors: {from: ethercat.wheel_sensors, to: ropod.wheel_sensors}
  wheel_commands: {from: ropod.wheel_commands, to: ethercat.wheel_commands}
  slave_states: {from: ethercat.slave_states, to: ethercat_watchdog.slave_states}
  working_counter: {from: ethercat.working_counter, to: ethercat_watchdog.working_counter}
coordination:
  nets:
    fault:
      places: {WATCHING: , FAULT: , ROPOD_RUNNING: , HAPTIC_RUNNING: }
      transitions: {}
      marking: {WATCHING: 1}
      terminal: [WATCHING]
  flag_maps:
    fault:
      net: fault
      tracking_sources: {ethercat_watchdog.slave_fault: FAULT, ropod.lcsm.running: ROPOD_RUNNING,
                         haptic.lcsm.running: HAPTIC_RUNNING}
      tracking_sinks: {ropod.stop: FAULT, haptic.robot_held: FAULT, haptic.resources_ready: ROPOD_RUNNING,
                       hand.go: HAPTIC_RUNNING}
"""


def _until(condition, what: str, timeout_s: float = 15.0):
    """Wait for a condition (a bound against hanging, not a timing claim)."""
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"never happened: {what}")
        time.sleep(0.005)


def _drives(wheel: dict) -> bool:
    """A wheel drives: its slave applies the outputs (OP, watchdog armed) and both motors are enabled."""
    return wheel["live"] and wheel["watchdog"] == 1 and wheel["enabled"]


# (fault, its arguments, how it is undone, how long the cause persists: until the robot has stopped)
FAULTS = (("lose", {"slave": 5}, "restore", True),
          ("al_error", {"slave": 3, "code": 0x0032, "hold_ms": 600}, None, True),
          ("trip_watchdog", {"slave": 6}, None, False),
          ("cut", {"slave": 5}, "reconnect", True))


@pytest.fixture(scope="module")
def recovery_run(tmp_path_factory):
    from .blocks import SetpointWatch
    from .runtime_helpers import compose

    tmp = tmp_path_factory.mktemp("ecat")
    ropod_log = tmp / "run-recovery" / "ropod.log"
    seen: dict = {"errors": []}
    SetpointWatch.zero_changes.clear()
    with Sandbox() as box:
        def status():
            return box.fault("status")

        def speed():
            return abs(status()["twist"][0])

        def all_op():
            return [s["state"] for s in status()["slaves"]] == [8] * 7

        def every_wheel_drives():
            return all(_drives(w) for w in status()["wheels"])

        def stops_raised():
            return ropod_log.read_text().count("stop raised") if ropod_log.exists() else 0

        def scenario(system):
            try:
                def calm() -> bool:  # driving, commanded to, and no stop held from an earlier fault
                    return (speed() > 0.1 and every_wheel_drives() and not system.flag("ropod.stop")
                            and SetpointWatch.zero_changes[-1:] == [False])

                _until(calm, "the robot drives on every wheel, no stop held")
                for fault, args, undo, lasting in FAULTS:
                    _until(calm, f"before {fault}: the robot drives on every wheel, no stop held")
                    zeros, stops = len(SetpointWatch.zero_changes), stops_raised()
                    box.fault(fault, **args)
                    _until(lambda: True in SetpointWatch.zero_changes[zeros:],
                           f"{fault}: the haptic controller commands no motion")
                    _until(lambda: stops_raised() > stops, f"{fault}: ropod.stop raised")
                    seen[fault] = {"held": True, "stop raised": True}
                    if lasting:
                        _until(lambda: speed() < 0.02, f"{fault}: the robot stops")
                        seen[fault]["stopped"] = True
                    if fault == "cut":  # the far wheels keep power, and trip for want of outputs
                        _until(lambda: [(s["al_status"], s["al_code"]) for s in status()["slaves"][5:]]
                               == [(0x14, 0x001B)] * 2, "cut: both far wheels trip their watchdogs")
                    if undo:
                        box.fault(undo, **args)
                    _until(lambda: all_op() and not system.flag("ropod.stop"), f"{fault}: every slave back in OP")
                    _until(every_wheel_drives, f"{fault}: every wheel drives again")
                    _until(lambda: speed() > 0.1, f"{fault}: the robot drives again")
                    seen[fault]["wheels"] = [_drives(w) for w in status()["wheels"]]
            except Exception as error:  # noqa: BLE001 - reported by the tests, not lost in a thread
                seen["errors"].append(str(error))
            finally:
                system.request_shutdown()

        def on_start(system):
            threading.Thread(target=scenario, args=(system,), daemon=True).start()

        result = compose(tmp, RECOVERY, clock="realtime", duration="90s", name="recovery", on_start=on_start,
                         shutdown_timeout="5s")
        seen["final_states"] = [s["state"] for s in box.fault("status")["slaves"]]
    return result, tmp / "run-recovery", seen


LASTING = {"held": True, "stop raised": True, "stopped": True, "wheels": [True] * 4}


def test_a_lost_wheel_cuts_off_the_wheel_behind_it_and_both_drive_again(recovery_run):
    result, run, seen = recovery_run
    assert not seen["errors"], seen["errors"]
    assert seen["lose"] == LASTING
    log = (run / "ethercat_watchdog.log").read_text()
    for line in ("wheel_3: OP -> NONE", "wheel_3: lost", "wheel_3: recovered", "wheel_3: reconfigured",
                 "wheel_4: OP -> NONE", "wheel_4: lost", "wheel_4: found again"):
        assert line in log


def test_an_al_error_and_a_watchdog_trip_are_acknowledged_back_to_op(recovery_run):
    result, run, seen = recovery_run
    assert not seen["errors"], seen["errors"]
    log = (run / "ethercat_watchdog.log").read_text()
    assert seen["al_error"] == LASTING
    assert "wheel_2: OP -> SAFE-OP+ERR (AL code 0x0032" in log and "wheel_2: acknowledging the error" in log
    assert "wheel_2: SAFE-OP -> OP" in log
    assert seen["trip_watchdog"] == {"held": True, "stop raised": True, "wheels": [True] * 4}
    assert "wheel_4: OP -> SAFE-OP+ERR (AL code 0x001B" in log and "wheel_4: SAFE-OP -> OP" in log


def test_a_cut_cable_leaves_the_far_wheels_in_safe_op_with_the_error_until_recovered(recovery_run):
    result, run, seen = recovery_run
    assert not seen["errors"], seen["errors"]
    assert seen["cut"] == LASTING
    log = (run / "ethercat_watchdog.log").read_text().split("wheel_3: OP -> NONE")[-1]  # the cut, not the loss
    for wheel in ("wheel_3", "wheel_4"):
        assert f"{wheel}: lost" in log and f"{wheel}: found again" in log
        assert f"{wheel}: NONE -> SAFE-OP+ERR (AL code 0x001B" in log
    assert "wheel_3: recovered" not in log  # it kept its address: nothing to recover


def test_the_run_ends_cleanly_with_every_slave_in_init(recovery_run):
    result, run, seen = recovery_run
    from hapticop.runtime.system import ExitStatus

    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    assert seen["final_states"] == [1] * 7
    assert "EtherCAT segment back in INIT" in (run / "ethercat.log").read_text()


# --- the command line -----------------------------------------------------------------------

def _hapticop(*args, timeout=120):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "hapticop.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def test_the_sandbox_command_runs_a_command_beside_the_emulator_and_passes_its_status():
    probe = ("import socket, subprocess, sys; "
             "socket.if_nametoindex('hapticop-ecat0'); "
             "out = subprocess.run([sys.executable, '-m', 'hapticop.cli', 'ethercat', 'fault', 'status'], "
             "capture_output=True, text=True).stdout; "
             "assert '\"name\": \"SWMC\"' in out, out; sys.exit(3)")
    import sys

    done = _hapticop("ethercat", "sandbox", "--", sys.executable, "-c", probe)
    assert done.returncode == 3, done.stderr
    assert not _interface_here("hapticop-ecat0")


def test_two_sandboxes_side_by_side_share_no_file():
    """Each sandbox's interface has the same name in its own namespace, so nothing it shares by file may be
    named after it: the command in a second sandbox reads its own emulator's truth, and leaves the first's."""
    import sys

    with Sandbox() as first:
        probe = ("import os, sys, numpy as np; "
                 "from hapticop.devices.ethercat.emulator.truth import TruthReader, truth_path; "
                 "path = truth_path('hapticop-ecat0'); "
                 f"assert str(path) != {str(first.truth)!r}, path; "
                 "assert str(path) == os.environ['HAPTICOP_ECAT_TRUTH'], path; "
                 "reader = TruthReader(path); reader.read(np.zeros(3), np.zeros(3)); reader.close(); sys.exit(3)")
        done = _hapticop("ethercat", "sandbox", "--", sys.executable, "-c", probe)
        assert done.returncode == 3, done.stderr
        assert first.truth.exists(), "the second sandbox took the first's truth file with it"
        assert first.fault("status")["slaves"], "the first emulator runs on"


def test_the_hallway_runs_with_the_real_master_in_the_sandbox(tmp_path):
    done = _hapticop("ethercat", "sandbox", "--", "hapticop-compose-placeholder")
    assert done.returncode == 127 and "no such command" in done.stderr
    import sys

    run = tmp_path / "run"
    done = _hapticop("ethercat", "sandbox", "--", sys.executable, "-m", "hapticop.cli", "compose",
                     "systems/hallway_ethercat.yaml", "--duration", "10s", "--run-dir", str(run),
                     # the simulators start, and the world judges the run as it cleans, in a process of
                     # their own at normal scheduling, which a busy machine serves last
                     "--shutdown-timeout", "30s")
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    assert "in OP: EK1100, EK1122, SWMC, SWMC, EK1122, SWMC, SWMC" in (run / "ethercat.log").read_text()
    assert ("PDO assignment read over CoE as expected: wheel_1, wheel_2, wheel_3, wheel_4"
            in (run / "ethercat.log").read_text())
    assert "distributed clocks: SYNC0 every 1000 us on wheel_1, wheel_2, wheel_3, wheel_4" in (
        run / "ethercat.log").read_text()
    assert "back in INIT" in (run / "ethercat.log").read_text()
    assert "all 7 slaves operational" in (run / "ethercat_watchdog.log").read_text()
    pose = np.load(run / "trajectory.npz")["pose"]  # the world's pose is the emulated robot's
    assert pose[-1, 0] - pose[0, 0] > 0.05  # the wheels, on SYNC0, drove it down the hallway


KILL_MAIN = r'''
"""Inside the sandbox: drive with the real master, SIGKILL the main process, watch the segment."""
import json, os, signal, subprocess, sys, time

def status():
    out = subprocess.run([sys.executable, "-m", "hapticop.cli", "ethercat", "fault", "status"],
                         capture_output=True, text=True).stdout
    return json.loads(out)

def until(condition, what, bound_s):
    deadline = time.monotonic() + bound_s  # a bound against hanging, not a timing claim
    while not condition():
        if time.monotonic() > deadline:
            print(json.dumps({"never": what, "status": status()}))
            sys.exit(1)
        time.sleep(0.05)

def descendants(pid):
    found, todo = [], [pid]
    while todo:
        here = todo.pop()
        for task in os.listdir(f"/proc/{here}/task"):
            try:
                with open(f"/proc/{here}/task/{task}/children") as f:
                    kids = [int(k) for k in f.read().split()]
            except OSError:
                kids = []
            found += kids
            todo += kids
    return found

def alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False

system = subprocess.Popen([sys.executable, "-m", "hapticop.cli", "compose", "systems/hallway_ethercat.yaml",
                           "--duration", "120s", "--run-dir", sys.argv[1]],
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
until(lambda: all(w["live"] and w["enabled"] for w in status()["wheels"]), "every wheel drives", 90)
children = descendants(system.pid)
os.kill(system.pid, signal.SIGKILL)
system.wait()
until(lambda: not any(alive(c) for c in children), "every child process of the killed system ends", 10)
final = status()
print(json.dumps({"children": len(children), "states": [s["state"] for s in final["slaves"]],
                  "outputs": final["outputs"], "wheels": final["wheels"]}))
'''


def test_when_the_main_process_is_killed_the_fieldbus_disables_the_drives_and_lets_the_segment_go(tmp_path):
    """The fieldbus process outlives a SIGKILLed main process only to leave its device safe: it
    writes drives-disabled outputs, takes every slave back to INIT and ends (not the slaves'
    own watchdogs tripping on a wire gone quiet, which is what a process that simply died leaves)."""
    import json
    import sys

    script = tmp_path / "kill_main.py"
    script.write_text(KILL_MAIN)
    done = _hapticop("ethercat", "sandbox", "--", sys.executable, str(script), str(tmp_path / "run"), timeout=180)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    assert seen["children"] >= 2  # the fieldbus and watchdog processes (and the simulation's)
    assert seen["states"] == [1] * 7, seen  # INIT, asked for: no SAFE-OP+ERROR from a tripped watchdog
    assert all(set(outputs) == {"0"} for outputs in seen["outputs"]), seen["outputs"]  # drives disabled, no current
