"""The TiM561 simulator answers like the device (byte-exact where captured) and streams like it."""

from __future__ import annotations

import select
import socket
from pathlib import Path

import numpy as np
import pytest

from hapticop.devices.sick import cola, scan
from hapticop.devices.sick.device_model import ANGLES_RAD, POINTS, room_ranges
from hapticop.devices.sick.simulator import TiMSimulator
from hapticop.devices.sick.stream import TelegramReader

HERE = Path(__file__).resolve().parent
REPLIES = HERE / "fixtures" / "sick" / "cola_a" / "replies"
SIM00 = HERE / "fixtures" / "sick" / "cola_a" / "tim561_sRA_LMDscandata_sim00.bin"
SHARED_REPLIES = HERE.parent.parent / "shared" / "testdata" / "sick" / "cola_a" / "replies"


def reply_capture(stem: str) -> bytes:
    local = (REPLIES / f"{stem}.bin").read_bytes()
    shared = SHARED_REPLIES / f"{stem}.bin"
    if shared.exists():
        assert shared.read_bytes() == local
    return local


class Peer:
    """A plain socket talking to a stepped simulator at a fixed simulated time."""

    def __init__(self, sim: TiMSimulator, t_ns: int = 0):
        self.sim, self.t = sim, t_ns
        self.sock = socket.create_connection((sim.host, sim.port), timeout=2)
        self.reader = TelegramReader()
        self.pending: list[bytes] = []
        self.wait(lambda: sim.connected)

    def wait(self, done, limit: int = 2000) -> None:
        for _ in range(limit):
            self.sim.step(self.t)
            if done():
                return
            ready, _, _ = select.select([self.sock], [], [], 0.001)
            if ready:
                data = self.sock.recv(65536)
                if not data:
                    self.closed = True
                self.pending += self.reader.push(data)
        raise AssertionError("no answer from the simulator")

    def ask(self, body: bytes | str, raw: bool = False) -> bytes:
        self.sock.sendall(body if raw else cola.frame(body))
        self.wait(lambda: bool(self.pending))
        return b"\x02" + self.pending.pop(0) + b"\x03"

    def silent(self, body: bytes, steps: int = 30) -> bool:
        self.sock.sendall(body)
        for _ in range(steps):
            self.sim.step(self.t)
            if select.select([self.sock], [], [], 0.002)[0]:
                self.pending += self.reader.push(self.sock.recv(65536))
        return not self.pending

    def run_until(self, t_end_ns: int, tick_ns: int = 1_000_000) -> list[bytes]:
        """Step simulated time forward, collecting every telegram."""
        bodies = []
        while self.t < t_end_ns:
            self.t += tick_ns
            self.sim.step(self.t)
            while select.select([self.sock], [], [], 0)[0]:
                data = self.sock.recv(65536)
                if not data:
                    return bodies
                bodies += self.reader.push(data)
        return bodies


@pytest.fixture
def sim():
    with TiMSimulator() as simulator:
        yield simulator


def test_replies_are_byte_exact_where_captured():
    with TiMSimulator(serial_number=16160456) as sim:
        peer = Peer(sim)
        assert peer.ask("sRI 0") == reply_capture("tim561_fw251_sRA_index0_deviceident")
        assert peer.ask(b"\x02sRI0\x03", raw=True) == reply_capture("tim561_fw251_sRA_index0_deviceident")
        assert peer.ask("sRN SerialNumber") == reply_capture("tim561_fw251_sRA_SerialNumber")
        assert peer.ask("sMN SetAccessMode 3 12345678") == reply_capture("tim561_fw251_sAN_SetAccessMode_0")
        assert peer.ask("sMN SetAccessMode 03 F4724744") == reply_capture("mrs6124_sAN_SetAccessMode_1")
        assert peer.ask("sWN EIHstCola 1") == reply_capture("mrs6124_sWA_EIHstCola")


def test_startup_replies_follow_the_notes(sim):
    peer = Peer(sim)
    assert peer.ask("sRN SCdevicestate") == b"\x02sRA SCdevicestate 1\x03"
    assert peer.ask("sRN LMPoutputRange") == b"\x02sRA LMPoutputRange 1 D05 FFF92230 225510\x03"
    assert peer.ask("sRN LocationName") == b"\x02sRA LocationName B not defined\x03"
    assert peer.ask("sRN FirmwareVersion") == b"\x02sRA FirmwareVersion 5 V2.51\x03"
    assert peer.ask("sRN ODpwrc") == b"\x02sRA ODpwrc 79\x03"
    assert peer.ask("sMN SetAccessMode 3 F4724744") == b"\x02sAN SetAccessMode 1\x03"
    assert peer.ask("sRN SCdevicestate") == b"\x02sRA SCdevicestate 0\x03"  # logged in: busy
    assert peer.ask("sWN EIHstCola 0") == b"\x02sWA EIHstCola\x03"
    assert peer.ask("sWN LMPoutputRange 1 D05 FFF92230 225510") == b"\x02sWA LMPoutputRange\x03"
    assert peer.ask("sWN LMDscandatacfg 1 0 1 1 0 0 0 0 0 0 0 1") == b"\x02sWA LMDscandatacfg\x03"
    assert peer.ask("sMN mEEwriteall") == b"\x02sAN mEEwriteall 1\x03"
    assert peer.ask("sMN LMCstartmeas") == b"\x02sAN LMCstartmeas 0\x03"
    assert peer.ask("sMN Run") == b"\x02sAN Run 1\x03"
    assert peer.ask("sRN SCdevicestate") == b"\x02sRA SCdevicestate 1\x03"
    assert peer.ask("sEN LMDscandata 1") == b"\x02sEA LMDscandata 1\x03"
    assert peer.ask("sEN LMDscandata 0") == b"\x02sEA LMDscandata 0\x03"


@pytest.mark.parametrize("request_body, code", [
    ("sXX Foo", "C"), ("sRN Nope", "3"), ("sMN Nope", "2"), ("sEN Nope 1", "F"),
    ("sMN LMCstartmeas", "1"), ("sWN LMPoutputRange 1 D05 FFF92230 225510", "A"), ("sWN Nope 1", "3"),
    ("sMN SetAccessMode", "8"), ("sRI G", "11"), ("sEN LMDscandata", "8"), ("sEN LMDscandata 2", "4"),
])
def test_errors_answer_sfa(sim, request_body, code):
    assert Peer(sim).ask(request_body) == b"\x02sFA " + code.encode() + b"\x03"


def test_out_of_range_output_range_is_refused_after_login(sim):
    peer = Peer(sim)
    peer.ask("sMN SetAccessMode 3 F4724744")
    assert peer.ask("sWN LMPoutputRange 1 2710 FFF92230 225510") == b"\x02sFA 4\x03"  # 1° is not a TiM561 step
    assert peer.ask("sWN LMPoutputRange 1 D05 FFF00000 225510") == b"\x02sFA 4\x03"  # below -45°
    assert peer.ask("sWN LMPoutputRange 1 D05 -450000 +2250000") == b"\x02sWA LMPoutputRange\x03"  # decimal


def test_noise_other_dialects_and_empty_frames_get_no_reply(sim):
    peer = Peer(sim)
    cola_b = b"\x02\x02\x02\x02\x00\x00\x00\x11sRN SCdevicestate\x5a"
    assert peer.silent(cola_b) and peer.silent(b"\x02\x03") and peer.silent(b"\xff\xfe garbage")
    assert peer.ask(b"hello\x02sRN SCdevicestate\x03", raw=True) == b"\x02sRA SCdevicestate 1\x03"


def test_stream_follows_the_section_9_checklist(sim):
    peer = Peer(sim)
    peer.ask("sEN LMDscandata 1")
    bodies = peer.run_until(1_000_000_000)
    assert len(bodies) == 15  # scans 1..15 leave at k/15 s; scan 0 left before the subscription
    capture = SIM00.read_bytes()[1:-1].split(b" ")
    headers = []
    for body in bodies:
        tokens = body.split(b" ")
        assert tokens[0] == b"sSN" and tokens[1:7] == capture[1:7] and tokens[11:26] == capture[11:26]
        assert tokens[26 + POINTS:] == [b"0", b"0", b"1", b"B", b"not", b"defined", b"0", b"0", b"0"]
        ranges, angles = np.empty(POINTS), np.empty(POINTS)
        headers.append(scan.parse_scan(body, ranges, angles))
        assert np.allclose(angles, ANGLES_RAD) and np.allclose(ranges, room_ranges(), atol=0.0005)
    for before, after in zip(headers, headers[1:]):
        assert after.telegram_counter - before.telegram_counter == 1
        assert after.time_since_startup_us - before.time_since_startup_us in (66_666, 66_667)
    for header in headers:
        assert header.scan_counter == header.telegram_counter + 2
        assert header.time_of_transmission_us - header.time_since_startup_us == 5000


def test_counters_and_clock_wrap():
    with TiMSimulator(uptime_us=(1 << 32) - 100_000, telegram_counter=0xFFFE) as sim:
        peer = Peer(sim)
        peer.ask("sEN LMDscandata 1")
        headers = [scan.parse_scan(b, np.empty(POINTS)) for b in peer.run_until(300_000_000)]
        assert [h.telegram_counter for h in headers] == [0xFFFF, 0, 1, 2]
        assert [h.scan_counter for h in headers] == [1, 2, 3, 4]
        assert headers[0].time_of_transmission_us > headers[1].time_of_transmission_us  # wrapped
        assert (headers[1].time_since_startup_us - headers[0].time_since_startup_us) % (1 << 32) in (66_666, 66_667)


def test_configuration_applies_after_run(sim):
    peer = Peer(sim)
    peer.ask("sMN SetAccessMode 3 F4724744")
    peer.ask("sWN LMPoutputRange 1 D05 0 1B7740")  # 0°..180° in the SICK frame
    peer.ask("sWN LMDscandatacfg 1 0 1 1 0 0 0 0 0 0 1 1")  # 16-bit RSSI, no name, time block
    assert peer.ask("sRN LMPoutputRange") == b"\x02sRA LMPoutputRange 1 D05 FFF92230 225510\x03"
    peer.ask("sMN Run")
    assert peer.ask("sRN LMPoutputRange") == b"\x02sRA LMPoutputRange 1 D05 0 1B7740\x03"
    telegram = peer.ask("sRN LMDscandata")
    first, last = -(-450000 // 3333), 2250000 // 3333  # the points of the fixed grid inside 0°..180°
    count = last - first + 1
    ranges, rssi = np.empty(count), np.empty(count)
    header = scan.parse_scan(telegram, ranges, out_rssi=rssi)
    assert header.command_type == "sRA" and header.dist.count == count == 540
    assert header.dist.start_angle == -450000 + first * 3333 == 3288
    assert header.rssi.name == "RSSI1" and header.device_name is None and header.timestamp[0] == 1970
    assert (rssi > 0).all()


def test_one_client_at_a_time_and_faults(sim):
    first = Peer(sim)
    second = socket.create_connection((sim.host, sim.port), timeout=2)
    for _ in range(50):
        sim.step(0)
        if sim.refused_connections:
            break
    assert sim.refused_connections == 1 and second.recv(10) == b""
    second.close()
    first.ask("sEN LMDscandata 1")
    sim.inject_garbage(b"\xffjunk")
    assert first.run_until(70_000_000)[0].startswith(b"sSN LMDscandata")
    assert first.reader.discarded_bytes == 5
    sim.drop_connection()
    assert first.sock.recv(10) == b"" and not sim.connected
