"""SOEM's recorded bring-up, replayed against the emulated segment in this process (no sockets, no root).

The trace (../shared/testdata/ethercat/soem_bringup_trace.json, and the shipped summary of it in
tests/fixtures/ethercat/) lists every kind of datagram pysoem sent while bringing the emulated ropod
segment up: command, register, length and how often. The replay sends each kind in SOEM's order
(count the slaves, reset their defaults, give out station addresses, read the SII, PRE-OP, program
SMs and FMMUs, SAFE-OP, OP with LRW cycles) and checks every working counter against what the
trace says: a broadcast counts every slave, an addressed datagram its one slave, the LRW 12. A
datagram kind the replay does not send, or sends and SOEM never did, fails it.
"""

from __future__ import annotations

import json
import re
import struct

import numpy as np
import pytest

from hapticop.devices.ethercat.emulator.ropod_segment import EK1100, EK1122, SWMC, RopodSegment, smart_wheel_identity
from hapticop.devices.ropod.pdo import RXPDO_BYTES, TXPDO_BYTES, Com1

from .conftest import FIXTURES, SHARED_TESTDATA
from .test_ethercat_emulator import answers, frame, u16

TRACE = SHARED_TESTDATA / "ethercat" / "soem_bringup_trace.json"
SHIPPED = FIXTURES / "ethercat" / "soem_bringup.json"
CODES = {"APRD": 1, "APWR": 2, "FPRD": 4, "FPWR": 5, "BRD": 7, "BWR": 8, "LRW": 12}
NAMES = {code: name for name, code in CODES.items()}
INIT, PREOP, SAFEOP, OP, ACK = 0x01, 0x02, 0x04, 0x08, 0x10
EEP_READ = 0x0100


def facts_from_trace(doc: dict) -> dict:
    """The shipped summary's facts, read from the recorded trace and its notes."""
    (count_row,) = [r for r in doc["by_register"] if (r["cmd"], int(r["ado"], 16)) == ("BRD", 0)]
    assert "WKC = slave count" in count_row["register"]  # the note the first check relies on
    lrw = doc["lrw"]
    return {"slaves": int(re.search(r"\((\d+) slaves", doc["what"]).group(1)),
            "wheels": int(re.search(r"= (\d+) x \(", lrw).group(1)),
            "datagrams": [{"cmd": r["cmd"], "ado": r["ado"], "len": r["len"], "count": r["count"]}
                          for r in doc["by_register"]],
            "lrw": {"count": doc["datagrams_by_command"]["LRW"],
                    "length": int(re.search(r"length (\d+)", lrw).group(1)),
                    "expected_wkc": int(re.search(r"expected WKC (\d+)", lrw).group(1))}}


def load(source: str) -> dict:
    if source == "shipped":
        return json.loads(SHIPPED.read_text())
    if not TRACE.exists():
        pytest.skip(f"the recorded trace is not here ({TRACE}); the shipped summary is replayed instead")
    return facts_from_trace(json.loads(TRACE.read_text()))


class Replay:
    """Sends datagrams one a frame to an in-process segment; each must be of a kind SOEM sent."""

    def __init__(self, facts: dict):
        self.facts = facts
        # the trace was taken from wheels without a mailbox or distributed clocks (its 'what' says so)
        self.model = RopodSegment(rng=np.random.default_rng(0), wheel=smart_wheel_identity(mailbox=False))
        self.kinds = {(d["cmd"], int(d["ado"], 16), d["len"]): d["count"] for d in facts["datagrams"]}
        self.sent: set[tuple[str, int, int]] = set()
        self.lrw_sent = 0
        self.now_ns = 0

    def send(self, cmd: int, adp: int, ado: int, data: bytes, wkc: int) -> bytes:
        kind = (NAMES[cmd], ado, len(data))
        if cmd == CODES["LRW"]:
            assert len(data) == self.facts["lrw"]["length"]
            self.lrw_sent += 1
        else:
            assert kind in self.kinds, f"{kind} is not a datagram SOEM sent in the trace"
            self.sent.add(kind)
        self.now_ns += 1_000_000
        payload = frame((cmd, adp & 0xFFFF, ado, data))
        assert self.model.segment.process(memoryview(payload), self.now_ns)
        (answer, got), = answers(payload)
        assert got == wkc, f"{NAMES[cmd]} 0x{ado:04X} ({len(data)} bytes, adp 0x{adp & 0xFFFF:04X}): " \
                           f"working counter {got}, the trace says {wkc}"
        return answer

    def kind_count(self, cmd: str, ado: int, length: int) -> int:
        return self.kinds[(cmd, ado, length)]


def replay(facts: dict) -> Replay:
    r = Replay(facts)
    n, wheels = facts["slaves"], facts["wheels"]
    BRD, BWR, APRD, APWR, FPRD, FPWR, LRW = (CODES[c] for c in ("BRD", "BWR", "APRD", "APWR", "FPRD", "FPWR", "LRW"))
    # detect: aliases off, every slave to INIT (acknowledging), count them
    r.send(BWR, 0, 0x0103, bytes(1), n)
    r.send(BWR, 0, 0x0120, u16(INIT | ACK), n)
    r.send(BRD, 0, 0x0000, bytes(2), n)
    # defaults: loop control, event mask, error counters, FMMUs, SMs, DC registers, EEPROM to the master
    for ado, length in ((0x0101, 1), (0x0200, 2), (0x0300, 8), (0x0600, 48), (0x0800, 32), (0x0910, 4),
                        (0x0930, 2), (0x0934, 2), (0x0981, 1), (0x0500, 1)):
        r.send(BWR, 0, ado, bytes(length), n)
    # station addresses by position, read back; each slave's DL control, PDI, alias, ports, features, DL status
    assert r.kind_count("APWR", 0x0010, 2) == n and r.kind_count("APRD", 0x0010, 2) == n
    stations = [0x1001 + p for p in range(n)]
    for p, station in enumerate(stations):
        r.send(APWR, -p, 0x0010, u16(station), 1)
        assert r.send(APRD, -p, 0x0010, bytes(2), 1) == u16(station)
        r.send(APWR, -p, 0x0100, bytes(2), 1)
        r.send(APRD, -p, 0x0140, bytes(2), 1)
    for station in stations:
        for ado in (0x0012, 0x0007, 0x0008):
            r.send(FPRD, station, ado, bytes(2), 1)
        dl_status = struct.unpack("<H", r.send(FPRD, station, 0x0110, bytes(2), 1))[0]
        assert dl_status & 0x0010  # a link on the port towards the master
    # the SII: identity words through the EEPROM interface, in 4- and 8-byte reads
    products, vendors = [], []
    for station in stations:
        r.send(FPWR, station, 0x0500, bytes(1), 1)
        for word, length, out in ((0x0A, 8, products), (0x08, 4, vendors)):
            r.send(FPWR, station, 0x0502, struct.pack("<HI", EEP_READ, word), 1)
            control = struct.unpack("<H", r.send(FPRD, station, 0x0502, bytes(2), 1))[0]
            assert not control & 0xF800  # not busy, no error: the data are there
            out.append(struct.unpack_from("<I", r.send(FPRD, station, 0x0508, bytes(length), 1))[0])
    assert products == [EK1100, EK1122, SWMC, SWMC, EK1122, SWMC, SWMC]
    assert vendors[0] == vendors[1] == vendors[4] == 2  # Beckhoff's couplers
    wheel_stations = [s for s, product in zip(stations, products) if product == SWMC]
    assert len(wheel_stations) == wheels
    # PRE-OP, slave by slave, each state read with its AL status code; then all at once
    for station in stations:
        r.send(FPWR, station, 0x0120, u16(PREOP | ACK), 1)
        status = r.send(FPRD, station, 0x0130, bytes(6), 1)
        assert (status[0], struct.unpack_from("<H", status, 4)[0]) == (PREOP, 0)
    assert r.send(BRD, 0, 0x0130, bytes(2), n)[0] == PREOP
    # the process data: SM0 outputs and SM1 inputs from the SII, FMMUs into one IO map (outputs first)
    assert r.kind_count("FPWR", 0x0800, 8) == r.kind_count("FPWR", 0x0600, 16) == wheels
    for k, station in enumerate(wheel_stations):
        r.send(FPWR, station, 0x0800, struct.pack("<HHBBBB", 0x1000, RXPDO_BYTES, 0x64, 0, 1, 0), 1)
        r.send(FPWR, station, 0x0808, struct.pack("<HHBBBB", 0x1100, TXPDO_BYTES, 0x20, 0, 1, 0), 1)
        r.send(FPWR, station, 0x0600,
               struct.pack("<IHBBHBBB3x", k * RXPDO_BYTES, RXPDO_BYTES, 0, 7, 0x1000, 0, 2, 1), 1)
        r.send(FPWR, station, 0x0610, struct.pack("<IHBBHBBB3x", wheels * RXPDO_BYTES + k * TXPDO_BYTES, TXPDO_BYTES,
                                                  0, 7, 0x1100, 0, 1, 1), 1)
    # SAFE-OP; valid outputs before OP (an LRW already counts 12), then OP and the cycles
    r.send(BWR, 0, 0x0120, u16(SAFEOP), n)
    assert r.send(BRD, 0, 0x0130, bytes(2), n)[0] == SAFEOP
    lrw = facts["lrw"]
    image = bytearray(lrw["length"])
    for k in range(wheels):
        struct.pack_into("<HH", image, k * RXPDO_BYTES, int(Com1.ENABLE1 | Com1.ENABLE2 | Com1.MODE_VELOCITY), k)
    r.send(LRW, 0, 0, bytes(image), lrw["expected_wkc"])
    r.send(BWR, 0, 0x0120, u16(OP), n)
    assert r.send(BRD, 0, 0x0130, bytes(2), n)[0] == OP
    for _ in range(lrw["count"] - 1):
        answer = r.send(LRW, 0, 0, bytes(image), lrw["expected_wkc"])
    for k, wheel in enumerate(r.model.wheels):
        assert bytes(wheel.output_buffer()) == bytes(image[k * RXPDO_BYTES:(k + 1) * RXPDO_BYTES])
        at = wheels * RXPDO_BYTES + k * TXPDO_BYTES
        assert answer[at:at + TXPDO_BYTES] == bytes(wheel.input_buffer())
    return r


@pytest.mark.parametrize("source", ["recorded", "shipped"])
def test_every_kind_of_datagram_soem_sent_is_answered_with_the_working_counter_it_got(source):
    facts = load(source)
    r = replay(facts)
    assert r.sent == set(r.kinds), f"kinds in the trace the replay never sent: {set(r.kinds) - r.sent}"
    assert r.lrw_sent == facts["lrw"]["count"]
    assert [s.state for s in r.model.slaves] == [OP] * facts["slaves"]
    assert all(wheel.outputs_live for wheel in r.model.wheels)


def test_the_shipped_summary_says_what_the_recorded_trace_says():
    recorded = load("recorded")
    assert json.loads(SHIPPED.read_text()) | {"about": None} == recorded | {"about": None}
