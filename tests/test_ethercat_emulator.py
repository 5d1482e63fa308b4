"""The emulated ESC and segment, frame by frame, without a network (no root needed).

A tiny master here builds datagrams byte by byte from the EtherCAT layout, so the emulator
is checked against the protocol, not against itself.
"""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from hapticop.devices.ethercat.emulator.esc import AL_CODE_INVALID_OUTPUT_CONFIG, AL_CODE_INVALID_STATE_CHANGE
from hapticop.devices.ethercat.emulator.ropod_segment import EK1100, EK1122, SWMC, RopodSegment
from hapticop.devices.ethercat.emulator.truth import TruthReader, TruthWriter
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES, Com1, rxpdo_view

from .conftest import FIXTURES, SHARED_TESTDATA

APRD, APWR, FPRD, FPWR, BRD, BWR, LRW = 1, 2, 4, 5, 7, 8, 12
NS = 1_000_000


def frame(*datagrams) -> bytearray:
    """An EtherCAT payload (after the EtherType) of (cmd, adp, ado, data) datagrams."""
    body = bytearray()
    for i, (cmd, adp, ado, data) in enumerate(datagrams):
        more = 0x8000 if i + 1 < len(datagrams) else 0
        body += struct.pack("<BBHHHH", cmd, i, adp, ado, len(data) | more, 0) + bytes(data) + b"\0\0"
    return bytearray(struct.pack("<H", len(body) | 0x1000)) + body


def answers(payload: bytearray) -> list[tuple[bytes, int]]:
    """(data, working counter) of each datagram."""
    out, at = [], 2
    while at < len(payload):
        length = struct.unpack_from("<H", payload, at + 6)[0]
        size = length & 0x07FF
        out.append((bytes(payload[at + 10:at + 10 + size]), struct.unpack_from("<H", payload, at + 10 + size)[0]))
        if not length & 0x8000:
            break
        at += 12 + size
    return out


def send(seg: RopodSegment, *datagrams, now=0):
    payload = frame(*datagrams)
    assert seg.segment.process(memoryview(payload), now)
    return answers(payload)


def u16(v):
    return struct.pack("<H", v)


@pytest.fixture
def seg():
    return RopodSegment(rng=np.random.default_rng(0))


def address(seg):
    """Station addresses 0x1001.. by position, as SOEM gives them."""
    for position in range(7):
        send(seg, (APWR, (-position) & 0xFFFF, 0x0010, u16(0x1001 + position)))


def eeprom_read(seg, station, word) -> bytes:
    send(seg, (FPWR, station, 0x0502, struct.pack("<HI", 0x0100, word)))
    return send(seg, (FPRD, station, 0x0508, bytes(8)))[0][0]


def request(seg, station, state, now=0):
    send(seg, (FPWR, station, 0x0120, u16(state)), now=now)
    data, _ = send(seg, (FPRD, station, 0x0130, bytes(6)), now=now)[0]
    return data[0], struct.unpack_from("<H", data, 4)[0]


def test_a_broadcast_read_counts_the_slaves_and_positions_address_them(seg):
    (data, wkc), = send(seg, (BRD, 0, 0x0000, bytes(2)))
    assert wkc == 7 and data[0] == 0x11
    address(seg)
    stations = [struct.unpack("<H", send(seg, (APRD, (-p) & 0xFFFF, 0x0010, bytes(2)))[0][0])[0] for p in range(7)]
    assert stations == [0x1001 + p for p in range(7)]
    assert send(seg, (FPRD, 0x1004, 0x0010, bytes(2)))[0] == (u16(0x1004), 1)
    assert send(seg, (FPRD, 0x2000, 0x0010, bytes(2)))[0][1] == 0  # nobody there


def test_the_sii_identifies_each_slave_through_the_eeprom_registers(seg):
    address(seg)
    products = [struct.unpack_from("<I", eeprom_read(seg, 0x1001 + p, 0x0A))[0] for p in range(7)]
    assert products == [EK1100, EK1122, SWMC, SWMC, EK1122, SWMC, SWMC]
    vendor = struct.unpack_from("<I", eeprom_read(seg, 0x1001, 0x08))[0]
    assert vendor == 2  # Beckhoff
    assert eeprom_read(seg, 0x1001, 0x18)[:4] == bytes(4)  # the coupler has no mailbox
    assert struct.unpack("<4H", eeprom_read(seg, 0x1003, 0x18)) == (0x1000, 128, 0x1080, 128)  # the wheels do
    assert struct.unpack_from("<H", eeprom_read(seg, 0x1003, 0x1C))[0] == 0x0004  # CoE


def _categories(eeprom: bytes) -> dict[int, bytes]:
    out, at = {}, 0x80
    while True:
        kind, words = struct.unpack_from("<HH", eeprom, at)
        if kind == 0xFFFF:
            return out
        out[kind] = eeprom[at + 4:at + 4 + 2 * words]
        at += 4 + 2 * words


def test_the_wheel_sii_categories_describe_the_ropod_pdo_layout(seg):
    cats = _categories(bytes(seg.wheels[0].eeprom))
    strings = cats[10]
    assert strings[0] >= 1 and strings[2:2 + strings[1]] == b"SWMC"  # string 1 is the name
    assert cats[30][3] == 1  # general: name index
    assert list(cats[40][:2]) == [1, 2]  # FMMU 0 outputs, FMMU 1 inputs
    assert cats[30][5] == 0x05  # general: CoE details, SDO and PDO assignment
    sms = [struct.unpack_from("<HHBBBB", cats[41], 8 * i) for i in range(4)]
    assert sms == [(0x1000, 128, 0x26, 0, 1, 1), (0x1080, 128, 0x22, 0, 1, 2),  # mailbox out, in
                   (0x1100, RXPDO_BYTES, 0x64, 0, 1, 3), (0x1180, TXPDO_BYTES, 0x20, 0, 1, 4)]
    for kind, sm, nbytes, entries in ((51, 2, RXPDO_BYTES, 9), (50, 3, TXPDO_BYTES, 40)):
        index, count, sync = struct.unpack_from("<HBB", cats[kind])
        bits = sum(cats[kind][8 + 8 * i + 5] for i in range(count))
        assert (count, sync, bits) == (entries, sm, 8 * nbytes)


def test_the_pdo_layout_matches_the_shared_data(seg):
    path = SHARED_TESTDATA / "ethercat" / "ropod_smartwheel_pdo.json"
    if not path.exists():
        path = FIXTURES / "ropod" / "ropod_smartwheel_pdo.json"  # the shipped copy
    spec = json.loads(path.read_text())
    cats = _categories(bytes(seg.wheels[0].eeprom))
    fields = spec["txpdo_inputs_slave_to_master"]["fields"]
    assert [cats[50][8 + 8 * i + 5] for i in range(len(fields))] == [8 * f["size"] for f in fields]


def program_mailboxes(seg):
    """What SOEM's config_init writes to a slave with a mailbox before PRE-OP: SM0 and SM1 in one datagram."""
    for position in (2, 3, 5, 6):
        send(seg, (FPWR, 0x1001 + position, 0x0800, struct.pack("<HHBBBBHHBBBB", 0x1000, 128, 0x26, 0, 1, 0,
                                                                 0x1080, 128, 0x22, 0, 1, 0)))


def test_the_al_state_machine_refuses_illegal_requests_until_acknowledged(seg):
    address(seg)
    program_mailboxes(seg)
    assert request(seg, 0x1003, 0x08) == (0x01 | 0x10, AL_CODE_INVALID_STATE_CHANGE)  # INIT -> OP
    assert request(seg, 0x1003, 0x02) == (0x11, AL_CODE_INVALID_STATE_CHANGE)  # ignored: not acknowledged
    assert request(seg, 0x1003, 0x12) == (0x02, 0)  # PRE-OP with ACK
    assert request(seg, 0x1003, 0x04) == (0x02 | 0x10, AL_CODE_INVALID_OUTPUT_CONFIG)  # no SM programmed


def program_wheel(seg, station, logical_out, logical_in):
    """What SOEM's config_map writes: SM2/SM3 from the SII, FMMU0 outputs, FMMU1 inputs."""
    send(seg, (FPWR, station, 0x0810, struct.pack("<HHBBBB", 0x1100, RXPDO_BYTES, 0x64, 0, 1, 0)),
         (FPWR, station, 0x0818, struct.pack("<HHBBBB", 0x1180, TXPDO_BYTES, 0x20, 0, 1, 0)),
         (FPWR, station, 0x0600, struct.pack("<IHBBHBBB3x", logical_out, RXPDO_BYTES, 0, 7, 0x1100, 0, 2, 1)),
         (FPWR, station, 0x0610, struct.pack("<IHBBHBBB3x", logical_in, TXPDO_BYTES, 0, 7, 0x1180, 0, 1, 1)))


def start_sync0(seg, station, start_ns=NS, cycle_ns=NS, now=0):
    """What SOEM's dcsync0 writes: cyclic unit off, ECAT control, start time, cycle, then SYNC0 on."""
    send(seg, (FPWR, station, 0x0981, bytes(1)), (FPWR, station, 0x0980, bytes(1)),
         (FPWR, station, 0x0990, struct.pack("<Q", start_ns)), (FPWR, station, 0x09A0, struct.pack("<I", cycle_ns)),
         (FPWR, station, 0x0981, bytes([0x03])), now=now)


def bring_up(seg):
    address(seg)
    program_mailboxes(seg)
    send(seg, (BWR, 0, 0x0120, u16(0x12)))  # PRE-OP with ACK, every slave
    for n, position in enumerate((2, 3, 5, 6)):
        station = 0x1001 + position
        program_wheel(seg, station, n * (RXPDO_BYTES + TXPDO_BYTES), n * (RXPDO_BYTES + TXPDO_BYTES) + RXPDO_BYTES)
        start_sync0(seg, station)
    send(seg, (BWR, 0, 0x0120, u16(0x04)))
    send(seg, (BWR, 0, 0x0120, u16(0x08)))


def test_lrw_moves_the_images_through_the_fmmus_with_working_counter_three_per_wheel(seg):
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)
    (_, wkc), = send(seg, (LRW, 0, 0, bytes(size)))
    assert wkc == 0  # nothing mapped in INIT
    bring_up(seg)
    assert [s.state for s in seg.slaves] == [8] * 7
    commands = bytearray(size)
    commands[0:4] = struct.pack("<HH", int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_VELOCITY), 0)
    (data, wkc), = send(seg, (LRW, 0, 0, commands), now=NS)
    assert wkc == 12
    assert bytes(seg.wheels[0].output_buffer()) == bytes(commands[:RXPDO_BYTES])
    assert data[RXPDO_BYTES:RXPDO_BYTES + TXPDO_BYTES] == bytes(seg.wheels[0].input_buffer())
    seg.step(NS)
    seg.step(2 * NS)
    assert rxpdo_view(seg.rx)["command1"][0] == 0x000B  # the live wheel drives with its outputs


def test_the_process_data_watchdog_drops_a_wheel_to_safe_op_with_code_0x001b(seg):
    bring_up(seg)
    wheel = seg.wheels[1]
    send(seg, (FPWR, 0x1004, 0x0420, u16(100)))  # 100 x 100 us = 10 ms
    assert wheel.watchdog_ns() == 10 * NS
    send(seg, (LRW, 0, 0, bytes(4 * (RXPDO_BYTES + TXPDO_BYTES))), now=NS)
    seg.tick(NS + 10 * NS)
    assert wheel.state == 8 and wheel.outputs_live
    seg.tick(NS + 11 * NS)
    assert (wheel.al_status, wheel.al_code) == (0x14, 0x001B) and not wheel.outputs_live
    seg.step(20 * NS)
    seg.step(21 * NS)
    assert not seg.rx[1].any()  # its drive gets nothing: the firmware's safe state
    assert request(seg, 0x1004, 0x14) == (0x04, 0)  # acknowledged back to SAFE-OP


def test_a_powered_off_wheel_takes_the_wheel_behind_it_off_the_line(seg):
    """wheel_3 (position 5) feeds wheel_4 (6): without power it passes no frame on. wheel_4 keeps
    power and its state, until its watchdog fires for want of outputs."""
    bring_up(seg)
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)
    send(seg, (LRW, 0, 0, bytes(size)), now=NS)
    seg.slaves[5].present = False
    assert send(seg, (BRD, 0, 0x0000, bytes(2)))[0][1] == 5
    (_, wkc), = send(seg, (LRW, 0, 0, bytes(size)), now=2 * NS)
    assert wkc == 6  # wheel_1 and wheel_2 only
    assert send(seg, (FPRD, 0x1007, 0x0130, bytes(2)))[0][1] == 0  # wheel_4 does not answer
    wheel_4 = seg.slaves[6]
    assert wheel_4.state == 8 and wheel_4.outputs_live  # still driving on the last outputs it had
    seg.tick(NS + 101 * NS)  # past the default 100 ms with no outputs: it trips
    assert (wheel_4.al_status, wheel_4.al_code) == (0x14, 0x001B) and not wheel_4.outputs_live
    seg.slaves[5].power_on()
    seg.slaves[5].present = True
    assert seg.slaves[5].state == 1 and seg.slaves[5].station == 0  # freshly powered: INIT, no address
    assert send(seg, (APRD, (-5) & 0xFFFF, 0x0010, bytes(2)))[0] == (u16(0), 1)
    assert send(seg, (APRD, (-6) & 0xFFFF, 0x0010, bytes(2)))[0] == (u16(0x1007), 1)  # kept its address
    data, wkc = send(seg, (FPRD, 0x1007, 0x0130, bytes(6)))[0]
    assert (data[0], struct.unpack_from("<H", data, 4)[0], wkc) == (0x14, 0x001B, 1)


def test_the_wiring_follows_the_ports_so_a_junction_branch_falls_alone(seg):
    assert seg.segment.upstream == [None, 0, 1, 2, 1, 4, 5]
    seg.slaves[2].present = False  # wheel_1: wheel_2 behind it goes too, the rear junction stays
    assert send(seg, (BRD, 0, 0x0000, bytes(2)))[0][1] == 5
    assert [s.name for s, r in zip(seg.slaves, seg.segment.reached()) if r] == ["EK1100", "EK1122", "EK1122",
                                                                               "SWMC", "SWMC"]
    seg.slaves[2].present = True
    seg.slaves[1].present = False  # the front junction: everything after the coupler
    assert send(seg, (BRD, 0, 0x0000, bytes(2)))[0][1] == 1
    assert seg.segment.behind(1) == [2, 3, 4, 5, 6] and seg.segment.behind(5) == [6]


def test_a_cut_cable_leaves_the_far_wheels_powered_until_they_return_in_safe_op_with_the_error(seg):
    bring_up(seg)
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)
    send(seg, (LRW, 0, 0, bytes(size)), now=NS)
    seg.segment.cut.add(5)
    assert send(seg, (BRD, 0, 0x0000, bytes(2)))[0][1] == 5
    assert send(seg, (LRW, 0, 0, bytes(size)), now=2 * NS)[0][1] == 6
    far = seg.slaves[5:7]
    assert [s.state for s in far] == [8, 8] and all(s.present for s in far)
    seg.tick(NS + 101 * NS)
    assert [(s.al_status, s.al_code) for s in far] == [(0x14, 0x001B)] * 2
    seg.segment.cut.discard(5)
    for station in (0x1006, 0x1007):  # addresses and error kept: SOEM acknowledges and asks for OP
        data, wkc = send(seg, (FPRD, station, 0x0130, bytes(6)))[0]
        assert (data[0], struct.unpack_from("<H", data, 4)[0], wkc) == (0x14, 0x001B, 1)
        assert request(seg, station, 0x14) == (0x04, 0)
    send(seg, (LRW, 0, 0, bytes(size)), now=200 * NS)
    for station in (0x1006, 0x1007):
        assert request(seg, station, 0x08, now=200 * NS) == (0x08, 0)
    assert all(s.outputs_live for s in far)


def test_the_watchdog_rearms_on_the_next_output_write_and_the_wheel_drives_again(seg):
    bring_up(seg)
    wheel = seg.wheels[1]
    size = 4 * (RXPDO_BYTES + TXPDO_BYTES)
    commands = bytearray(size)
    for n in range(4):
        struct.pack_into("<HH", commands, n * (RXPDO_BYTES + TXPDO_BYTES),
                         int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_VELOCITY), 0)
    send(seg, (LRW, 0, 0, commands), now=NS)
    assert send(seg, (FPRD, 0x1004, 0x0440, bytes(2)))[0][0] == u16(1)
    wheel.trip_watchdog()
    assert send(seg, (FPRD, 0x1004, 0x0440, bytes(2)))[0][0] == u16(0)
    assert (wheel.al_status, wheel.al_code) == (0x14, 0x001B)
    assert request(seg, 0x1004, 0x14) == (0x04, 0)  # acknowledged
    send(seg, (LRW, 0, 0, commands), now=2 * NS)
    assert send(seg, (FPRD, 0x1004, 0x0440, bytes(2)))[0][0] == u16(1)  # re-armed by the write
    assert request(seg, 0x1004, 0x08) == (0x08, 0)
    assert wheel.outputs_live
    send(seg, (LRW, 0, 0, commands), now=3 * NS)
    seg.step(3 * NS)
    seg.step(4 * NS)
    assert rxpdo_view(seg.rx)["command1"][1] == 0x000B  # its drive gets its commands again


def test_a_request_for_init_is_honoured_from_an_error_and_clears_it(seg):
    bring_up(seg)
    wheel = seg.wheels[0]
    wheel.trip_watchdog()
    assert request(seg, 0x1003, 0x01) == (0x01, 0)  # no acknowledge needed
    wheel = seg.wheels[2]
    wheel.raise_error(0x0032, until_ns=50 * NS)  # even while the cause persists
    assert request(seg, 0x1006, 0x02, now=NS) == (0x14, 0x0032)
    assert request(seg, 0x1006, 0x01, now=NS) == (0x01, 0)
    assert request(seg, 0x1006, 0x02, now=NS) == (0x02, 0)  # and the state machine moves on from there


def test_a_persisting_al_error_cannot_be_acknowledged_until_its_cause_is_gone(seg):
    bring_up(seg)
    wheel = seg.wheels[2]
    wheel.raise_error(0x0032, until_ns=5 * NS)
    assert request(seg, 0x1006, 0x14, now=4 * NS) == (0x14, 0x0032)
    assert request(seg, 0x1006, 0x14, now=6 * NS) == (0x04, 0)


def test_the_true_pose_is_shared_through_a_file(tmp_path):
    writer = TruthWriter(tmp_path / "truth")
    reader = TruthReader(tmp_path / "truth")
    pose, twist = np.zeros(3), np.zeros(3)
    assert reader.read(pose, twist) == 0
    writer.write(1.5, np.array([1.0, 2.0, 0.5]), np.array([0.3, 0.0, 0.1]))
    assert reader.read(pose, twist) == 2
    assert pose.tolist() == [1.0, 2.0, 0.5] and twist.tolist() == [0.3, 0.0, 0.1]
    reader.close()
    writer.close()
    assert not (tmp_path / "truth").exists()


# -- the emulator's control socket survives whatever it is sent --------------------------------------
def test_the_control_socket_answers_bad_requests_and_keeps_the_segment_running(tmp_path):
    """Not JSON, JSON that is not an object, nesting past Python's stack, bytes that are not UTF-8, a
    line too long, nonsense values: each gets an error, and the next good request is answered."""
    import socket as socketlib
    import threading
    import time

    from hapticop.devices.ethercat.emulator.server import MAX_REQUEST_BYTES, FrameServer, control

    server = FrameServer("unused", RopodSegment(rng=np.random.default_rng(0)), control_path=tmp_path / "control.sock",
                         log=lambda _: None)
    listener = server._listen()
    stop = threading.Event()

    def loop():  # the segment loop's side of the control channel, as run() does between frames
        while not stop.is_set():
            server.answer_requests()
            time.sleep(0.001)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        def raw(payload: bytes) -> dict:
            with socketlib.socket(socketlib.AF_UNIX, socketlib.SOCK_STREAM) as sock:
                sock.settimeout(10)
                sock.connect(str(tmp_path / "control.sock"))
                sock.sendall(payload)
                answer = b""
                while not answer.endswith(b"\n"):
                    chunk = sock.recv(65536)
                    assert chunk, "the control socket closed without answering"
                    answer += chunk
            return json.loads(answer)

        bad = [b"[1]\n", b'"status"\n', b"null\n", b"not json\n", b"\xff\xfe\n", b"[" * 100_000 + b"\n",
               b'{"op": "al_error", "slave": 2, "code": 26, "hold_ms": 1e400}\n',
               b'{"op": "lose", "slave": [1, 2]}\n', b'{"op": "late", "delay_us": {}, "frames": 1}\n',
               b"x" * (MAX_REQUEST_BYTES + 10) + b"\n"]
        for payload in bad:
            answer = raw(payload)
            assert answer["ok"] is False and answer["error"], payload[:40]
        path = tmp_path / "control.sock"
        nonsense = [{"op": "lose", "slave": 7}, {"op": "lose", "slave": True}, {"op": "lose", "slave": 5.0},
                    {"op": "lose", "slave": "5"}, {"op": "cut"}, {"op": "cut", "slave": -1},
                    {"op": "reconnect", "slave": 5}, {"op": "restore", "slave": 5}]
        for bad_request in nonsense:
            answer = control(path, bad_request)
            assert answer["ok"] is False and answer["error"], bad_request
        assert control(path, {"op": "ping"})["ok"] is True
        status = control(path, {"op": "status"})
        assert all(slave["present"] and slave["reached"] for slave in status["slaves"])  # nothing changed
        assert status["cut"] == []
        # the faults themselves, and the state they leave, through the same socket
        assert control(path, {"op": "cut", "slave": 5})["ok"] is True
        assert control(path, {"op": "cut", "slave": 5})["ok"] is False  # already cut
        assert control(path, {"op": "lose", "slave": 2})["ok"] is True
        assert control(path, {"op": "lose", "slave": 2})["ok"] is False  # already off
        status = control(path, {"op": "status"})
        assert [s["reached"] for s in status["slaves"]] == [True, True, False, False, True, False, False]
        assert [s["present"] for s in status["slaves"]] == [True, True, False, True, True, True, True]
        assert status["cut"] == [5] and [w["live"] for w in status["wheels"]] == [False, False, False, False]
        assert control(path, {"op": "reconnect", "slave": 5})["ok"] is True
        assert control(path, {"op": "restore", "slave": 2})["ok"] is True
        assert all(s["reached"] for s in control(path, {"op": "status"})["slaves"])
    finally:
        stop.set()
        thread.join(5)
        server.running = False
        listener.close()
