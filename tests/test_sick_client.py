"""ColaClient against the simulator over loopback, in simulated time: start-up, scans on schedule,
reconnect, resync, stall and timeout detection, backoff; plus a short real-time run."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest

from hapticop.devices.sick import commands, scan
from hapticop.devices.sick.client import ClientState, ColaClient
from hapticop.devices.sick.device_model import ANGLES_RAD, POINTS, room_ranges
from hapticop.devices.sick.simulator import TiMSimulator

MS = 1_000_000
LIVE = (ClientState.STARTING, ClientState.STREAMING)


class Lockstep:
    """Steps the simulator and polls the client alternately, one 1 ms tick of simulated time each.

    Loopback delivers within the sending call on Linux, so each side sees the other's bytes in
    the same tick; the short real waits below are only a safety net for a loaded machine.
    """

    def __init__(self, sim: TiMSimulator, client: ColaClient):
        self.sim, self.client = sim, client
        self.t = 0
        self.client_sent = 0
        self.arrivals: list[int] = []  # tick at which each scan was parsed
        self.scans: list[tuple[int, np.ndarray, scan.ScanHeader]] = []
        self.failures: list[tuple[int, str]] = []  # (tick, last_error) when the client gave up a connection
        self._ranges, self._angles = np.empty(POINTS), np.empty(POINTS)

    def tick(self) -> None:
        t, sim, client = self.t, self.sim, self.client
        expected = sim.bytes_received + self.client_sent
        sent = sim.step(t)
        for _ in range(400):
            if not sim.connected or sim.bytes_received >= expected:
                break
            time.sleep(0.0005)
            sent += sim.step(t)
        expected = client.bytes_received + sent
        sent_before, state_before = client.bytes_sent, client.state
        new = client.poll(t)
        for _ in range(400):
            if client.state not in LIVE or client.bytes_received >= expected:
                break
            time.sleep(0.0005)
            new += client.poll(t)
        self.client_sent = client.bytes_sent - sent_before
        if state_before is not ClientState.DISCONNECTED and client.state is ClientState.DISCONNECTED:
            self.failures.append((t, client.last_error))
        if new:
            self.arrivals += [t] * new
            assert client.latest_scan(self._ranges, self._angles)
            self.scans.append((t, self._ranges.copy(), client.header))
        self.t += MS

    def run_until(self, t_end_ns: int) -> None:
        while self.t < t_end_ns:
            self.tick()


def expected_arrivals(sim: TiMSimulator, start_ns: int, end_ns: int) -> list[int]:
    """Tick (1 ms grid) at which each scan sent in [start, end) is parsed."""
    times = []
    k = sim.scan_index(start_ns) + 1
    while sim.scan_time_ns(k) < end_ns:
        times.append(math.ceil(sim.scan_time_ns(k) / MS) * MS)
        k += 1
    return times


@pytest.fixture
def rig():
    taken: dict[int, np.ndarray] = {}

    def world(t_ns: int) -> np.ndarray:  # a room whose front wall moves, so every scan differs
        taken[t_ns] = room_ranges(front=3.0 + 0.5 * math.sin(t_ns / 1e8))
        return taken[t_ns]

    clock = {"t": 0}
    with TiMSimulator(ranges_m=world) as sim:
        client = ColaClient(sim.host, sim.port, clock_ns=lambda: clock["t"])
        loop = Lockstep(sim, client)
        loop.taken = taken
        yield loop
        client.close()


def test_scans_arrive_on_schedule_with_the_callbacks_ranges(rig):
    rig.run_until(1000 * MS)
    client, sim = rig.client, rig.sim
    assert client.state is ClientState.STREAMING and client.last_error == ""
    assert rig.arrivals == expected_arrivals(sim, 0, 1000 * MS) and len(rig.arrivals) == 14
    for (t, ranges, header), k in zip(rig.scans, range(1, 15)):
        taken = rig.taken[sim.scan_time_ns(k) - 5 * MS]  # the callback saw the scan instant
        assert np.abs(ranges - taken).max() <= 0.0005 + 1e-12  # mm quantisation
        assert header.telegram_counter == 0x3E22 + k
    assert np.allclose(client.angles_rad, ANGLES_RAD)
    assert (client.reconnects, client.bad_telegrams, client.discarded_bytes, client.stalls) == (0, 0, 0, 0)
    assert not client.latest_scan(np.empty(POINTS))  # nothing new since the last copy


def test_stepped_runs_are_deterministic_with_noise():
    def run() -> list[np.ndarray]:
        with TiMSimulator(noise_std_m=0.01, rng=np.random.default_rng(7)) as sim:
            with ColaClient(sim.host, sim.port, clock_ns=lambda: 0) as client:
                loop = Lockstep(sim, client)
                loop.run_until(400 * MS)
                return [ranges for _, ranges, _ in loop.scans]

    first, second = run(), run()
    assert len(first) == 5 and all(np.array_equal(a, b, equal_nan=True) for a, b in zip(first, second))
    assert 0.007 < np.nanstd(first[0] - room_ranges()) < 0.013


def test_reconnects_after_a_dropped_connection(rig):
    rig.run_until(300 * MS)
    scans = rig.client.scans
    rig.sim.drop_connection()
    rig.run_until(301 * MS)
    assert rig.failures == [(300 * MS, "connection closed by the scanner")]
    rig.run_until(1000 * MS)
    client = rig.client
    assert client.state is ClientState.STREAMING and client.reconnects == 1 and rig.sim.connections == 2
    # back 100 ms (first backoff) later, re-configured and subscribed within a few ticks
    assert rig.arrivals[scans:] == expected_arrivals(rig.sim, 410 * MS, 1000 * MS)


def test_resynchronises_after_garbage_without_reconnecting(rig):
    rig.run_until(200 * MS)
    garbage = b"\xff\x00noise\x03" + b"\x02sSN LMDscandata 1 1 1078AAA\x03" + b"\x02broken frame"
    rig.sim.inject_garbage(garbage)
    rig.run_until(1000 * MS)
    client = rig.client
    assert client.bad_telegrams == 1  # the bogus scan; the broken frame is dropped by the framer
    assert client.discarded_bytes == len(b"\xff\x00noise\x03") + len(b"\x02broken frame")
    assert client.reconnects == 0 and rig.arrivals == expected_arrivals(rig.sim, 0, 1000 * MS)


def test_detects_a_stalled_stream_and_recovers(rig):
    rig.run_until(300 * MS)
    last_scan = rig.arrivals[-1]
    rig.sim.stall(until_ns=800 * MS)
    rig.run_until(1500 * MS)
    client = rig.client
    assert client.stalls == 1 and client.reconnects == 1 and client.state is ClientState.STREAMING
    # the watchdog fires at the first poll more than three scan periods after the last scan
    assert rig.failures == [(last_scan + 200 * MS, "stream stalled: no scan for 0.200 s")]
    after = [t for t in rig.arrivals if t > last_scan]  # back when the stall ends, on the same grid
    assert after[0] == 800 * MS and after == expected_arrivals(rig.sim, 799 * MS, 1500 * MS)
    assert client.scan_host_ns == rig.arrivals[-1]


def test_reply_timeout_then_recovery(rig):
    rig.sim.mute()
    rig.run_until(1050 * MS)  # the login went out at 1 ms: no reply by 1001 ms
    client = rig.client
    assert rig.failures == [(1002 * MS, "no reply to 'sMN SetAccessMode 3 F4724744' within 1 s")]
    assert client.timeouts == 1 and client.state is ClientState.DISCONNECTED
    rig.sim.mute(False)
    rig.run_until(2000 * MS)
    assert client.state is ClientState.STREAMING and client.reconnects == 1


def test_a_refusal_reads_clearly_and_the_client_retries():
    with TiMSimulator() as sim:
        bad_range = commands.startup_sequence(output_range=commands.OutputRange(step=10000))
        client = ColaClient(sim.host, sim.port, startup=bad_range)
        loop = Lockstep(sim, client)
        loop.run_until(50 * MS)
        assert client.device_errors == 1 and client.state is ClientState.DISCONNECTED
        assert "sFA 4 = LOCALCONDITIONFAILED" in client.last_error and "LMPoutputRange" in client.last_error
        client.close()
        wrong = commands.startup_sequence(hash_hex="00000000")
        client = ColaClient(sim.host, sim.port, startup=wrong)
        Lockstep(sim, client).run_until(50 * MS)
        assert "login refused" in client.last_error
        client.close()


def test_backoff_doubles_up_to_the_limit():
    with socket.socket() as probe:  # a port nobody listens on
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    client = ColaClient("127.0.0.1", port, backoff=(0.1, 0.5))
    attempts = []
    for t in range(0, 3000 * MS, MS):
        connects = client.connects
        client.poll(t)
        if client.connects > connects:
            attempts.append(t // MS)
    gaps = [b - a for a, b in zip(attempts, attempts[1:])]
    # each delay runs from the failure, seen at the attempt's poll or the next one
    assert all(0 <= gap - want <= 1 for gap, want in zip(gaps, [100, 200, 400, 500, 500, 500]))
    assert len(gaps) >= 6 and client.state is ClientState.DISCONNECTED
    assert "ECONNREFUSED" in client.last_error
    client.close()


def test_minimal_startup_just_subscribes(rig):
    client = ColaClient(rig.sim.host, rig.sim.port, startup=commands.startup_sequence(configure=False))
    rig.client = client
    rig.run_until(300 * MS)
    assert client.state is ClientState.STREAMING and client.scans == 4 and rig.sim.commands == 1
    client.close()


@pytest.mark.timeout(30)
def test_real_time_threaded_simulator_and_a_1khz_poll_loop():
    with TiMSimulator(noise_std_m=0.005, rng=np.random.default_rng(1)).start() as sim:
        client = ColaClient(sim.host, sim.port)
        ranges = np.empty(POINTS, np.float32)
        end = time.monotonic() + 20  # a bound on a hang, not a speed requirement: 8 scans take about 0.6 s
        while client.scans < 8 and time.monotonic() < end:
            client.poll()
            client.latest_scan(ranges)
            time.sleep(0.001)
        assert client.state is ClientState.STREAMING and client.scans >= 8, client.last_error
        assert np.nanmax(np.abs(ranges - room_ranges())) < 0.05
        # a poll never waits on the network: its socket never blocks (how long a poll takes is the
        # benchmarks' business, bench/micro_sick.py, not a test's)
        assert client._sock.getblocking() is False and client._sock.gettimeout() == 0.0
        client.close()
