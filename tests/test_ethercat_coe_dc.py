"""The smart wheels' CoE mailbox and distributed clocks, datagram by datagram (no root needed).

Requests are built byte by byte from the mailbox, CoE and SDO layouts (ETG.1000.6) and sent
the way SOEM sends them: the whole receive mailbox in one FPWR, the answer fetched with one
FPRD of the whole send mailbox once SM1's status says it is full.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from hapticop.devices.ethercat.emulator.clocks import port_times
from hapticop.devices.ethercat.emulator.esc import AL_CODE_INVALID_OUTPUT_CONFIG
from hapticop.devices.ethercat.emulator.ropod_segment import RopodSegment
from hapticop.devices.ropod.pdo import RXPDO_BYTES, RXPDO_ENTRY_BITS, TXPDO_BYTES, TXPDO_ENTRY_BITS

from .test_ethercat_emulator import (
    APRD,
    BWR,
    FPRD,
    FPWR,
    LRW,
    NS,
    address,
    bring_up,
    program_mailboxes,
    program_wheel,
    request,
    send,
    start_sync0,
    u16,
)

FRMW = 14
WHEEL = 0x1003  # the first smart wheel's station address (bus position 2)
MBX_OUT, MBX_IN, MBX = 0x1000, 0x1080, 128
ABORT = 0x80


@pytest.fixture
def seg():
    return RopodSegment(rng=np.random.default_rng(0))


@pytest.fixture
def preop(seg):
    address(seg)
    program_mailboxes(seg)
    send(seg, (BWR, 0, 0x0120, u16(0x12)))
    assert [s.state for s in seg.slaves] == [2] * 7
    return seg


def sdo(command: int, index: int, subindex: int, data: bytes = bytes(4), counter: int = 1) -> bytes:
    """A whole receive mailbox holding one CoE SDO request (service 2)."""
    coe = struct.pack("<HBHB", 2 << 12, command, index, subindex) + data
    return (struct.pack("<HHBB", len(coe), 0, 0, 0x03 | counter << 4) + coe).ljust(MBX, b"\0")


def sm_status(seg, station, sm) -> int:
    return send(seg, (FPRD, station, 0x0805 + 8 * sm, bytes(1)))[0][0][0]


def post(seg, mailbox: bytes, station=WHEEL) -> int:
    return send(seg, (FPWR, station, MBX_OUT, mailbox))[0][1]


def fetch(seg, station=WHEEL) -> tuple[bytes, int]:
    return send(seg, (FPRD, station, MBX_IN, bytes(MBX)))[0]


def exchange(seg, mailbox: bytes) -> tuple[int, int, bytes]:
    """Post a request, fetch its answer: (mailbox type, SDO command, the SDO's data after index/subindex)."""
    assert post(seg, mailbox) == 1
    assert sm_status(seg, WHEEL, 1) & 0x08  # the answer is there
    data, wkc = fetch(seg)
    assert wkc == 1
    length, _, _, kind = struct.unpack_from("<HHBB", data)
    return kind & 0x0F, data[8], data[12:6 + length]


def upload(seg, index, subindex) -> tuple[int, bytes]:
    """(SDO command, value): an expedited answer's value cut to the size its command gives."""
    kind, command, data = exchange(seg, sdo(0x40, index, subindex))
    assert kind == 0x03
    if command != ABORT and command & 0x02:
        return command, data[:4 - (command >> 2 & 0x03)]
    return command, data


def download(seg, index, subindex, value: bytes) -> tuple[int, bytes]:
    """Expedited, size indicated."""
    _, command, data = exchange(seg, sdo(0x23 | (4 - len(value)) << 2, index, subindex, value.ljust(4, b"\0")))
    return command, data


def abort_code(answer: tuple[int, bytes]) -> int:
    command, data = answer
    assert command == ABORT
    return struct.unpack("<I", data)[0]


# --- the mailbox ----------------------------------------------------------------------------

def test_an_expedited_upload_answers_byte_for_byte_and_is_read_once(preop):
    assert post(preop, sdo(0x40, 0x1018, 2)) == 1
    assert sm_status(preop, WHEEL, 0) & 0x08 == 0  # the application took the request
    assert sm_status(preop, WHEEL, 1) & 0x08  # and its answer waits in SM1
    data, wkc = fetch(preop)
    assert wkc == 1
    length, address_, channel, kind = struct.unpack_from("<HHBB", data)
    assert (length, address_, channel, kind & 0x0F) == (10, 0, 0, 0x03) and 1 <= kind >> 4 <= 7
    service, command, index, subindex, value = struct.unpack_from("<HBHBI", data, 6)
    assert (service >> 12, command, index, subindex, value) == (3, 0x43, 0x1018, 2, 0x01705011)
    assert sm_status(preop, WHEEL, 1) & 0x08 == 0  # reading it emptied the send mailbox
    assert fetch(preop)[1] == 0  # a second read is refused: no working counter


def test_uploads_give_the_identity_the_sm_types_and_the_pdo_assignment(preop):
    assert upload(preop, 0x1018, 0) == (0x4F, bytes([4]))  # one byte: three unused, n = 3
    assert upload(preop, 0x1000, 0) == (0x43, bytes(4))
    assert upload(preop, 0x1008, 0) == (0x43, b"SWMC")
    assert upload(preop, 0x1C00, 0) == (0x4F, bytes([4]))
    assert [upload(preop, 0x1C00, sm)[1][0] for sm in range(1, 5)] == [1, 2, 3, 4]  # mailbox out/in, outputs, inputs
    assert upload(preop, 0x1C12, 0)[1] == bytes([1]) and upload(preop, 0x1C13, 0)[1] == bytes([1])
    assert upload(preop, 0x1C12, 1) == (0x4B, u16(0x1600))
    assert upload(preop, 0x1C13, 1) == (0x4B, u16(0x1A00))
    for pdo, bits in ((0x1600, RXPDO_ENTRY_BITS), (0x1A00, TXPDO_ENTRY_BITS)):
        count = upload(preop, pdo, 0)[1][0]
        words = [struct.unpack("<I", upload(preop, pdo, sub)[1])[0] for sub in range(1, count + 1)]
        assert tuple(w & 0xFF for w in words) == bits  # the ropod's packed structs, field by field
        assert [w >> 8 & 0xFF for w in words] == list(range(1, count + 1))
        assert {w >> 16 for w in words} == {0x7000 if pdo == 0x1600 else 0x6000}
    assert sum(RXPDO_ENTRY_BITS) == 8 * RXPDO_BYTES and sum(TXPDO_ENTRY_BITS) == 8 * TXPDO_BYTES


def test_a_normal_upload_carries_its_size_and_data_in_one_mailbox(preop):
    command, data = upload(preop, 0x100A, 0)
    assert command == 0x41  # normal transfer, size indicated
    size = struct.unpack_from("<I", data)[0]
    assert data[4:4 + size] == b"hapticop emulator" and len(data) == 4 + size


def test_unknown_objects_wrong_sizes_and_read_only_entries_are_aborted_with_their_codes(preop):
    assert abort_code(upload(preop, 0x2000, 0)) == 0x06020000  # object does not exist
    assert abort_code(upload(preop, 0x1018, 5)) == 0x06090011  # subindex does not exist
    assert abort_code(download(preop, 0x1C12, 0, struct.pack("<I", 1))) == 0x06070012  # too long for UNSIGNED8
    assert abort_code(download(preop, 0x1C12, 1, b"\x00")) == 0x06070013  # too short for UNSIGNED16
    assert abort_code(download(preop, 0x1018, 1, struct.pack("<I", 7))) == 0x06010002  # read only
    assert abort_code(download(preop, 0x1C12, 1, u16(0x1601))) == 0x06090030  # no such RxPDO
    kind, command, data = exchange(preop, sdo(0x50, 0x1018, 0))  # complete access: not offered
    assert (command, struct.unpack("<I", data)[0]) == (ABORT, 0x06010000)
    _, command, data = exchange(preop, sdo(0x60, 0x1018, 1))  # a segment request with no transfer open
    assert (command, struct.unpack("<I", data)[0]) == (ABORT, 0x05040001)
    abort = sdo(0x40, 0x2000, 0)
    assert post(preop, abort) == 1
    data, _ = fetch(preop)
    assert struct.unpack_from("<H", data, 6)[0] >> 12 == 2  # an abort travels as an SDO request


def test_other_mailbox_protocols_get_a_mailbox_error(preop):
    foe = (struct.pack("<HHBB", 6, 0, 0, 0x04 | 1 << 4) + bytes(6)).ljust(MBX, b"\0")
    assert post(preop, foe) == 1
    data, wkc = fetch(preop)
    assert wkc == 1 and data[5] & 0x0F == 0x00  # mailbox type: error
    assert struct.unpack_from("<HH", data, 6) == (1, 0x0002)  # unsupported protocol


def test_a_full_mailbox_refuses_writes_until_the_answer_is_fetched(preop):
    assert post(preop, sdo(0x40, 0x1018, 1)) == 1  # answered at once: SM1 full
    assert post(preop, sdo(0x40, 0x1018, 2, counter=2)) == 1  # waits in SM0: nowhere to answer
    assert sm_status(preop, WHEEL, 0) & 0x08 and sm_status(preop, WHEEL, 1) & 0x08
    assert post(preop, sdo(0x40, 0x1018, 3, counter=3)) == 0  # SM0 full: refused, not written
    first, _ = fetch(preop)
    assert first[11] == 1 and struct.unpack_from("<I", first, 12)[0] == 0  # vendor 0 (not published)
    assert sm_status(preop, WHEEL, 0) & 0x08 == 0 and sm_status(preop, WHEEL, 1) & 0x08  # the second is answered
    second, wkc = fetch(preop)
    assert wkc == 1 and second[11] == 2 and struct.unpack_from("<I", second, 12)[0] == 0x01705011
    assert fetch(preop)[1] == 0  # the third was never taken


def test_a_lost_answer_comes_back_when_the_master_toggles_the_repeat_request(preop):
    assert post(preop, sdo(0x40, 0x1018, 2)) == 1
    lost, wkc = fetch(preop)  # the frame that carried it never came back, say
    assert wkc == 1 and fetch(preop)[1] == 0  # SM1 is empty now
    status, activate = send(preop, (FPRD, WHEEL, 0x080D, bytes(2)))[0][0]
    assert send(preop, (FPWR, WHEEL, 0x080D, bytes([status, activate ^ 0x02])))[0][1] == 1
    assert send(preop, (FPRD, WHEEL, 0x080F, bytes(1)))[0][0][0] & 0x02 == (activate ^ 0x02) & 0x02  # acknowledged
    assert sm_status(preop, WHEEL, 1) & 0x08  # the answer is back in SM1
    again, wkc = fetch(preop)
    assert wkc == 1 and again == lost
    # the acknowledge follows the request only: the master cannot write the PDI control register
    assert send(preop, (FPWR, WHEEL, 0x080F, bytes([0xFF])))[0][1] == 1
    assert send(preop, (FPRD, WHEEL, 0x080F, bytes(1)))[0][0][0] & 0x02 == (activate ^ 0x02) & 0x02


def test_the_pdo_assignment_is_writable_in_pre_op_only_and_sizes_the_sync_manager(preop):
    assert download(preop, 0x1C12, 0, b"\x00") == (0x60, bytes(4))
    assert upload(preop, 0x1C12, 0)[1] == b"\x00"
    program_wheel(preop, WHEEL, 0, RXPDO_BYTES)
    start_sync0(preop, WHEEL)
    assert request(preop, WHEEL, 0x04) == (0x12, AL_CODE_INVALID_OUTPUT_CONFIG)  # SM2 is 36 bytes, assigned 0
    assert download(preop, 0x1C12, 0, b"\x01")[0] == 0x60
    assert request(preop, WHEEL, 0x14) == (0x04, 0)  # acknowledged, SAFE-OP
    assert abort_code(download(preop, 0x1C12, 0, b"\x00")) == 0x08000022  # not in SAFE-OP


def test_pre_op_needs_the_mailbox_sync_managers_of_the_sii(seg):
    address(seg)
    assert request(seg, WHEEL, 0x02) == (0x11, 0x0016)  # SM0/SM1 not programmed: invalid mailbox configuration
    assert request(seg, 0x1001, 0x02) == (0x02, 0)  # the coupler has no mailbox
    program_mailboxes(seg)
    assert request(seg, WHEEL, 0x12) == (0x02, 0)


def test_init_empties_the_mailbox(preop):
    assert post(preop, sdo(0x40, 0x1018, 1)) == 1
    send(preop, (FPWR, WHEEL, 0x0120, u16(0x01)))
    assert sm_status(preop, WHEEL, 1) & 0x08 == 0 and fetch(preop)[1] == 0


# --- distributed clocks ---------------------------------------------------------------------

def test_only_the_wheels_report_distributed_clocks(seg):
    address(seg)
    features = [struct.unpack("<H", send(seg, (FPRD, 0x1001 + p, 0x0008, bytes(2)))[0][0])[0] for p in range(7)]
    assert [bool(f & 0x04) for f in features] == [False, False, True, True, False, True, True]


def test_a_bwr_to_0x0900_latches_when_the_frame_passed_each_port(seg):
    address(seg)
    send(seg, (BWR, 0, 0x0900, bytes(4)), now=5 * NS)
    times = [struct.unpack("<4I", send(seg, (FPRD, 0x1001 + p, 0x0900, bytes(16)))[0][0]) for p in (2, 3, 5, 6)]
    unit = [struct.unpack("<Q", send(seg, (FPRD, 0x1001 + p, 0x0918, bytes(8)))[0][0])[0] for p in (2, 3, 5, 6)]
    wheel_1, wheel_2, wheel_3, wheel_4 = times
    assert unit == [t[0] for t in times] and unit[0] > 5 * NS  # port 0 when the frame arrived, after 2 slaves
    assert wheel_1[0] < wheel_2[0] < wheel_3[0] < wheel_4[0]  # along the line
    assert wheel_1[0] < wheel_2[0] < wheel_1[1]  # wheel 2 hangs off wheel 1's port 1: the frame returns later
    expected = port_times([s.ports for s in seg.slaves])
    assert [t[0] - wheel_1[0] for t in times] == [expected[p][0] - expected[2][0] for p in (2, 3, 5, 6)]


def test_system_time_is_local_time_plus_the_offset_and_a_written_time_is_compared(seg):
    address(seg)
    send(seg, (FPWR, WHEEL, 0x0920, struct.pack("<Q", 10**15)))
    arrival = port_times([s.ports for s in seg.slaves])[2][0]
    (data, wkc), = send(seg, (FPRD, WHEEL, 0x0910, bytes(8)), now=7 * NS)
    assert wkc == 1 and struct.unpack("<Q", data)[0] == 10**15 + 7 * NS + arrival
    send(seg, (FPWR, WHEEL, 0x0910, struct.pack("<Q", 10**15 + 7 * NS + arrival + 300)), now=7 * NS)
    assert struct.unpack("<I", send(seg, (FPRD, WHEEL, 0x092C, bytes(4)))[0][0])[0] == 300  # received is ahead
    send(seg, (FPWR, WHEEL, 0x0910, struct.pack("<Q", 10**15 + 7 * NS + arrival - 300)), now=7 * NS)
    assert struct.unpack("<I", send(seg, (FPRD, WHEEL, 0x092C, bytes(4)))[0][0])[0] == 0x80000000 | 300
    for register, value in ((0x0928, 550), (0x0930, 0x1000), (0x0934, 0x04)):
        size = 4 if register == 0x0928 else 2 if register == 0x0930 else 1
        send(seg, (FPWR, WHEEL, register, value.to_bytes(size, "little")))
        assert int.from_bytes(send(seg, (FPRD, WHEEL, register, bytes(size)))[0][0], "little") == value


def test_the_frmw_after_an_lrw_distributes_the_reference_clock_without_changing_the_lrw_count(seg):
    bring_up(seg)
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)
    answers = send(seg, (LRW, 0, 0, bytes(size)), (FRMW, WHEEL, 0x0910, bytes(8)), now=3 * NS)
    (_, lrw_wkc), (time, frmw_wkc) = answers
    assert lrw_wkc == 12
    assert frmw_wkc == 7  # the reference reads, the six others write
    reference = seg.wheels[0].clock
    assert struct.unpack("<Q", time)[0] == reference.system_time()


def test_safe_op_is_refused_with_0x0030_until_sync0_runs(preop):
    program_wheel(preop, WHEEL, 0, RXPDO_BYTES)
    assert request(preop, WHEEL, 0x04) == (0x12, 0x0030)  # no SYNC0: invalid DC SYNC configuration
    send(preop, (FPWR, WHEEL, 0x0990, struct.pack("<Q", NS)), (FPWR, WHEEL, 0x09A0, struct.pack("<I", NS)),
         (FPWR, WHEEL, 0x0981, bytes([0x01])))  # cyclic unit on, SYNC0 off
    assert request(preop, WHEEL, 0x14) == (0x12, 0x0030)
    start_sync0(preop, WHEEL, start_ns=NS, now=2 * NS)  # a start time already past never fires
    assert send(preop, (FPRD, WHEEL, 0x0984, bytes(1)))[0][0] == b"\x04"
    assert request(preop, WHEEL, 0x14) == (0x12, 0x0030)
    start_sync0(preop, WHEEL, start_ns=3 * NS, cycle_ns=100_000, now=2 * NS)  # faster than the firmware runs
    assert request(preop, WHEEL, 0x14) == (0x12, 0x0035)
    start_sync0(preop, WHEEL, start_ns=3 * NS, now=2 * NS)
    assert send(preop, (FPRD, WHEEL, 0x0984, bytes(1)))[0][0] == b"\x01"  # first pulse pending
    assert request(preop, WHEEL, 0x14) == (0x04, 0)


def test_a_wheel_on_sync0_takes_commands_and_publishes_sensors_on_the_pulses_only(seg):
    address(seg)
    program_mailboxes(seg)
    send(seg, (BWR, 0, 0x0120, u16(0x12)))
    for n, position in enumerate((2, 3, 5, 6)):
        program_wheel(seg, 0x1001 + position, n * (RXPDO_BYTES + TXPDO_BYTES),
                      n * (RXPDO_BYTES + TXPDO_BYTES) + RXPDO_BYTES)
        start_sync0(seg, 0x1001 + position, start_ns=10 * NS, cycle_ns=10 * NS)
    send(seg, (BWR, 0, 0x0120, u16(0x04)))
    send(seg, (BWR, 0, 0x0120, u16(0x08)))
    assert [s.state for s in seg.slaves] == [8] * 7
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)

    def command(value: int, now: int) -> None:
        frame = bytearray(size)
        frame[0:2] = u16(value)
        send(seg, (LRW, 0, 0, frame), now=now)

    seg.step(1 * NS)
    command(0x0001, 2 * NS)
    seg.step(3 * NS)
    assert seg.rx[0][0] == 0 and seg.sampled[0] is False  # no pulse yet: the firmware has not run
    inputs_before = bytes(seg.wheels[0].input_buffer())
    seg.step(10 * NS)  # the first pulse
    assert seg.rx[0][0] == 0x01 and seg.sampled[0] is True
    command(0x0003, 11 * NS)
    seg.step(12 * NS)
    seg.step(19 * NS)
    assert seg.rx[0][0] == 0x01  # held until the next pulse
    seg.step(20 * NS)
    assert seg.rx[0][0] == 0x03
    assert bytes(seg.wheels[0].input_buffer()) != inputs_before  # sensors published on a pulse


def test_power_on_clears_the_clock_and_the_mailbox(preop):
    wheel = preop.wheels[0]
    start_sync0(preop, WHEEL, start_ns=3 * NS)
    download(preop, 0x1C12, 0, b"\x00")
    wheel.power_on()
    assert wheel.clock.next_sync0 is None and wheel.mailbox.sdo.objects.values(0x1C12) == [0x1600]
    assert send(preop, (APRD, (-2) & 0xFFFF, 0x0008, bytes(2)))[0][0][0] & 0x04
    assert send(preop, (FPRD, 0, 0x0981, bytes(1)))[0] == (b"\x00", 1)  # no station address, no SYNC0
