"""The ROS 2 bridge against an independent ROS 2 client (zenoh-ros2-sdk, tests/ros2_client.py, in a process of
its own), over Zenoh on loopback: directly (peer) and through a Zenoh router (client mode, as with rmw_zenohd).

The client lists hapticop's node and topics through their liveliness tokens and decodes what hapticop
publishes; hapticop decodes what the client publishes. A hostile participant writes wrong types, malformed
CDR, values that are not finite, samples without rmw_zenoh's attachment and stale ones: each is refused and
counted, and the next good sample is delivered.
"""

from __future__ import annotations

import json
import math
import os
import queue
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from hapticop.network import transport
from hapticop.ros2 import attachment, names
from hapticop.ros2.messages import Codec
from hapticop.runtime.supervisor import ExitStatus
from hapticop.testing import BlockHarness
from tests.runtime_helpers import run_until

PATIENCE_S = 60.0  # a bound on hangs on a loaded machine, never a speed requirement
CLIENT = Path(__file__).parent / "ros2_client.py"
TWIST = "geometry_msgs/msg/Twist"
HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"  # Twist's in Jazzy (golden.json)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Client:
    """tests/ros2_client.py in a process of its own; its JSON lines gathered as they come."""

    def __init__(self, port: int, role: str) -> None:
        env = {**os.environ, "GIT_TERMINAL_PROMPT": "0", "ROS_DOMAIN_ID": "0"}
        self.stderr = tempfile.TemporaryFile("w+")  # a client that fails says why (its traceback)
        self.process = subprocess.Popen([sys.executable, str(CLIENT), str(port), role], stdout=subprocess.PIPE,
                                        stderr=self.stderr, text=True, env=env)
        self.lines: queue.Queue = queue.Queue()
        self.seen: list[dict] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            try:
                self.lines.put(json.loads(line))
            except json.JSONDecodeError:
                continue

    def drain(self) -> list[dict]:
        while True:
            try:
                self.seen.append(self.lines.get_nowait())
            except queue.Empty:
                return self.seen

    def lines_since(self) -> list[dict]:
        """The lines that came since the last call."""
        seen = len(self.seen)
        return self.drain()[seen:]

    def wait(self, condition, what: str) -> dict:
        deadline = time.monotonic() + PATIENCE_S
        while True:
            for line in self.drain():
                if condition(line):
                    return line
            assert self.process.poll() is None, f"the ROS 2 client ended ({self.process.returncode}) before: {what}"
            assert time.monotonic() < deadline, f"never within {PATIENCE_S:g} s: {what}"
            time.sleep(0.02)

    def errors(self) -> str:
        self.stderr.seek(0)
        return self.stderr.read()[-2000:]

    def close(self) -> None:
        self.process.kill()
        self.process.wait(timeout=PATIENCE_S)
        self.stderr.close()


def router(port: int):
    """A Zenoh router on loopback, as `rmw_zenohd` would be."""
    return transport.session([f"tcp/127.0.0.1:{port}"], [], mode="router")


SYSTEM = """
version: 1
name: ros2_echo
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, echo]}}
  ros2: {period: 5ms, deploy: process, schedules: {0: [ros2]}}
activities:
  mediator: {block: mediator}
  echo: {block: echo, params: {dtype: float64, shape: [3], unit: "m/s, m/s, rad/s"}}
  ros2:
    block: ros2_bridge
    params:
      node: hapticop
      MODE
      subscribe:
        cmd_in: {topic: /cmd_in, type: geometry_msgs/msg/Twist, qos: {reliability: best_effort, depth: 1}}
      publish:
        cmd_out: {topic: /cmd_out, type: geometry_msgs/msg/Twist, rate: 50Hz}
streams:
  cmd_in: {from: ros2.cmd_in, to: [echo.input], max_age: 200ms}
  cmd_out: {from: echo.output, to: [ros2.cmd_out], max_age: 200ms}
"""


def _echo_through(tmp_path, client_port: int, mode: str, system: str = SYSTEM) -> None:
    """hapticop's system echoes the client's /cmd_in to /cmd_out; the client sees the node and both topics."""
    client = Client(client_port, "probe")
    try:
        def round_trip(system) -> bool:
            lines = client.drain()
            echoed = any(line.get("cmd_out") == [0.25, 0.0, 0.5] for line in lines)
            listed = any("hapticop" in line.get("nodes", []) and ["/cmd_out", [TWIST]] in line.get("topics", [])
                         and ["hapticop", "MP", HASH, "::,10:,:,:,,"] in line["endpoints"].get("/cmd_out", [])
                         and ["hapticop", "MS", HASH, "2::,1:,:,:,,"] in line["endpoints"].get("/cmd_in", [])
                         for line in lines)
            seen["echoed"] |= echoed
            seen["listed"] |= listed
            return seen["echoed"] and seen["listed"]

        seen = {"echoed": False, "listed": False}
        try:
            result = run_until(tmp_path, system.replace("MODE", mode), round_trip,
                               "the client's twist echoed back, and hapticop's node and topics listed")
        except AssertionError as error:
            raise AssertionError(f"{error} (seen: {seen}; the client's last lines: {client.drain()[-3:]}; "
                                 f"its errors: {client.errors()!r})") from None
        assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
        log = (tmp_path / "run-c" / "system.log").read_text()
        pids = {line.rsplit(" ", 1)[1] for line in log.splitlines() if "runs in process" in line}
        assert len(pids) == 1 and str(os.getpid()) not in pids  # the bridge's own process, not the loops'
    finally:
        client.close()


def test_an_independent_client_sees_hapticops_node_and_topics_peer_to_peer(tmp_path):
    port = _free_port()
    _echo_through(tmp_path, port, f"listen: [tcp/127.0.0.1:{port}]")


def test_through_a_zenoh_router_in_client_mode(tmp_path):
    port = _free_port()
    hub = router(port)
    try:
        _echo_through(tmp_path, port, f"mode: client\n      connect: [tcp/127.0.0.1:{port}]")
    finally:
        hub.close()


# -- what the bridge refuses -----------------------------------------------------------
class Hostile:
    """The bridge stepped by hand (a BlockHarness), a router, and a hostile participant on it."""

    def __init__(self, tmp_path: Path) -> None:
        port = _free_port()
        self.hub = router(port)
        self.harness = BlockHarness("ros2_bridge", {
            "mode": "client", "connect": [f"tcp/127.0.0.1:{port}"],
            "subscribe": {"cmd": {"topic": "/cmd_vel", "type": TWIST, "max_age": "300ms"},
                          "scan": {"topic": "/scan", "type": "sensor_msgs/msg/LaserScan", "shape": [4]}}},
            name="ros2", run_dir=tmp_path)
        self.harness.block.create()
        self.harness.block.configure_resources()
        self.intruder = transport.session([], [f"tcp/127.0.0.1:{port}"], mode="client")
        self.senders: dict[str, transport.Sender] = {}
        self.key = names.data_key(0, "/cmd_vel", TWIST, "jazzy")
        self.twist = Codec(TWIST, "jazzy", "float64", (3,))
        self.sequence = 0
        self.delivered: list[list[float]] = []

    def close(self) -> None:
        self.harness.clean()
        self.intruder.close()
        self.hub.close()

    def put(self, key: str, payload: bytes, stamp_ns: int | None = None, attach: bool = True) -> None:
        if key not in self.senders:
            self.senders[key] = transport.Sender(self.intruder, key, reliable=True)
        self.sequence += 1
        extra = attachment.pack(self.sequence, time.time_ns() if stamp_ns is None else stamp_ns, bytes(16))
        self.senders[key].put(payload, extra if attach else None)

    def step(self) -> None:
        self.harness.block.compute()
        self.harness.advance()
        port = self.harness.outputs.cmd
        if port.published > len(self.delivered):
            self.delivered.append(port.value.tolist())

    def refused(self, why: str) -> int:
        return sum(n for reason, n in self.harness.block.refusals["cmd"].by_reason.items() if reason.startswith(why))

    def refuse(self, why: str, send) -> None:
        before = self.refused(why)
        deadline = time.monotonic() + PATIENCE_S
        while self.refused(why) <= before:
            assert time.monotonic() < deadline, f"nothing refused as '{why}' within {PATIENCE_S} s"
            send()
            for _ in range(5):
                self.step()
                time.sleep(0.002)

    def follows(self, value: list[float]) -> None:
        deadline = time.monotonic() + PATIENCE_S
        while not self.delivered or self.delivered[-1] != value:
            assert time.monotonic() < deadline, f"{value} not delivered within {PATIENCE_S} s"
            self.put(self.key, self.twist.encode(np.array(value), time.time_ns()))
            self.step()
            time.sleep(0.002)


@pytest.fixture
def hostile(tmp_path):
    h = Hostile(tmp_path)
    yield h
    h.close()


def test_bad_samples_are_refused_counted_and_the_next_good_one_delivered(hostile):
    h = hostile
    h.follows([0.1, 0.0, 0.2])
    humble = names.data_key(0, "/cmd_vel", TWIST, "humble")
    stamped = names.data_key(0, "/cmd_vel", "geometry_msgs/msg/TwistStamped", "jazzy")
    good = h.twist.encode(np.array([0.3, 0.0, 0.0]), 0)
    h.refuse("another type or type hash", lambda: h.put(humble, good))
    h.refuse("another type or type hash", lambda: h.put(stamped, good))
    h.refuse("malformed CDR", lambda: h.put(h.key, good[:-3]))
    h.refuse("not finite", lambda: h.put(h.key, h.twist.encode(np.array([math.nan, 0.0, 0.0]), 0)))
    h.refuse("not finite", lambda: h.put(h.key, h.twist.encode(np.array([0.0, 0.0, math.inf]), 0)))
    h.refuse("no rmw_zenoh attachment", lambda: h.put(h.key, good, attach=False))
    h.refuse("stale", lambda: h.put(h.key, good, stamp_ns=time.time_ns() - 2_000_000_000))
    h.refuse("source time in the future", lambda: h.put(h.key, good, stamp_ns=time.time_ns() + 5_000_000_000))
    assert h.delivered[-1] == [0.1, 0.0, 0.2]  # none of them got through
    h.follows([0.4, 0.0, -0.1])  # and the bridge goes on
    scan = Codec("sensor_msgs/msg/LaserScan", "jazzy", "float32", (5,))
    scan_key = names.data_key(0, "/scan", "sensor_msgs/msg/LaserScan", "jazzy")
    deadline = time.monotonic() + PATIENCE_S
    while h.harness.block.refusals["scan"].by_reason.get("5 ranges, not 4", 0) == 0:
        assert time.monotonic() < deadline, "a scan of another length was never refused"
        h.put(scan_key, scan.encode(np.ones(5, np.float32), time.time_ns()))
        h.step()
        time.sleep(0.002)
    assert h.harness.outputs.refused.value == sum(r.total for r in h.harness.block.refusals.values())


def test_a_late_sample_arrives_as_old_as_it_is_so_a_readers_max_age_counts_its_time_in_ros2(hostile):
    """A twist (or a scan, an odometry) sent 250 ms ago is accepted (the option's max_age is 300 ms) but stamped
    with its source time on this host's clock: a reader's stream with `max_age: 200ms` finds it stale, so a
    late scan is no force and a late odometry no motion, however fast the bridge took it."""
    h = hostile
    h.follows([0.1, 0.0, 0.2])
    h.harness.advance(1_000_000_000)  # this host's clock well past the sample's age (stamps are not negative)
    stamps: list[int] = []

    class Stamps:  # a reader's end of the stream: the stamp each sample is published with
        def push(self, value, stamp_ns: int, origins) -> None:
            stamps.append(stamp_ns)

    h.harness.outputs.cmd.transports.append(Stamps())
    deadline = time.monotonic() + PATIENCE_S
    while h.delivered[-1] != [0.5, 0.0, 0.0]:
        assert time.monotonic() < deadline, "the late twist was never delivered"
        h.put(h.key, h.twist.encode(np.array([0.5, 0.0, 0.0]), 0), stamp_ns=time.time_ns() - 250_000_000)
        h.step()
        time.sleep(0.002)
    assert h.harness.clock.now_ns() - stamps[-1] >= 250_000_000


def test_a_stale_command_is_published_as_a_stop(tmp_path):
    """With no valid sample on its input, a command topic carries zeros at its rate (`stale: zero`)."""
    port = _free_port()
    hub = router(port)
    harness = BlockHarness("ros2_bridge", {
        "mode": "client", "connect": [f"tcp/127.0.0.1:{port}"],
        "publish": {"cmd": {"topic": "/cmd_vel", "type": TWIST, "rate": "100Hz"}}}, name="ros2", run_dir=tmp_path)
    listener = transport.session([], [f"tcp/127.0.0.1:{port}"], mode="client")
    try:
        receiver = transport.Receiver(listener, names.data_key(0, "/cmd_vel", TWIST, "jazzy"), 16)
        harness.block.create()
        harness.block.configure_resources()
        twist, out = Codec(TWIST, "jazzy", "float64", (3,)), np.full(3, 9.0)
        deadline = time.monotonic() + PATIENCE_S
        while (sample := receiver.take_sample()) is None:
            assert time.monotonic() < deadline, "nothing published"
            harness.block.compute()
            harness.advance(20_000_000)
            time.sleep(0.005)
        key, payload, extra = sample
        assert twist.decode(payload, out) is None and out.tolist() == [0.0, 0.0, 0.0]
        sequence, _, gid = attachment.unpack(extra)
        assert sequence >= 1 and len(gid) == 16
    finally:
        harness.clean()
        listener.close()
        hub.close()


def test_humble_keys_carry_no_hash_and_jazzys_are_refused(tmp_path):
    """With `distro: humble` the key ends in TypeHashNotSupported: Jazzy's publisher is told apart and counted."""
    port = _free_port()
    hub = router(port)
    harness = BlockHarness("ros2_bridge", {
        "mode": "client", "connect": [f"tcp/127.0.0.1:{port}"], "distro": "humble",
        "subscribe": {"cmd": {"topic": "/cmd_vel", "type": TWIST}}}, name="ros2", run_dir=tmp_path)
    writer = transport.session([], [f"tcp/127.0.0.1:{port}"], mode="client")
    try:
        harness.block.create()
        harness.block.configure_resources()
        twist = Codec(TWIST, "humble", "float64", (3,))
        senders = {d: transport.Sender(writer, names.data_key(0, "/cmd_vel", TWIST, d), reliable=True)
                   for d in names.DISTROS}
        refusals = harness.block.refusals["cmd"].by_reason
        deadline = time.monotonic() + PATIENCE_S
        while not (harness.outputs.cmd.value.tolist() == [0.5, 0.0, 0.25] and refusals):
            assert time.monotonic() < deadline, f"humble's sample not delivered, or jazzy's not refused: {refusals}"
            for distro, value in (("jazzy", [9.0, 0.0, 0.0]), ("humble", [0.5, 0.0, 0.25])):
                senders[distro].put(twist.encode(np.array(value), 0), attachment.pack(1, time.time_ns(), bytes(16)))
            harness.block.compute()
            harness.advance()
            time.sleep(0.005)
        assert list(refusals) == [
            "another type or type hash: geometry_msgs::msg::dds_::Twist_/" + HASH]
    finally:
        harness.clean()
        writer.close()
        hub.close()


def test_a_sample_is_sent_at_the_rate_with_its_own_stamp_each_time(tmp_path):
    """The newest sample goes out at every slot (a base wants its command repeated), each time with the
    stamp of the loop's step that made it, a new sequence number, and the port's values."""
    port = _free_port()
    hub = router(port)
    harness = BlockHarness("ros2_bridge", {
        "mode": "client", "connect": [f"tcp/127.0.0.1:{port}"],
        "publish": {"cmd": {"topic": "/cmd_vel", "type": "geometry_msgs/msg/TwistStamped", "rate": "100Hz"}}},
        name="ros2", run_dir=tmp_path)
    listener = transport.session([], [f"tcp/127.0.0.1:{port}"], mode="client")
    try:
        receiver = transport.Receiver(listener, names.data_key(0, "/cmd_vel", "geometry_msgs/msg/TwistStamped",
                                                               "jazzy"), 64)
        harness.configure()
        harness.feed("cmd", [0.5, 0.0, 0.25])
        got = []
        deadline = time.monotonic() + PATIENCE_S
        while len(got) < 3:
            assert time.monotonic() < deadline, f"{len(got)} of 3 samples published"
            harness.step()
            harness.advance(10_000_000)
            while (sample := receiver.take_sample()) is not None:
                got.append(sample)
            time.sleep(0.002)
        store = names.typestore("jazzy")
        messages = [store.deserialize_cdr(payload, "geometry_msgs/msg/TwistStamped") for _, payload, _ in got]
        stamps = {(m.header.stamp.sec, m.header.stamp.nanosec) for m in messages}
        assert len(stamps) == 1  # one sample, one stamp
        assert all([m.twist.linear.x, m.twist.angular.z] == [0.5, 0.25] for m in messages)
        sequences = [attachment.unpack(extra)[0] for _, _, extra in got]
        assert sequences == sorted(set(sequences))
    finally:
        harness.clean()
        listener.close()
        hub.close()
