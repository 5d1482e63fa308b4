"""What a bridge refuses, over real Zenoh on loopback: two bridges (an operator's and a robot's) stepped
by hand, and a third peer that writes whatever it likes on every key the robot's bridge listens on.

Malformed samples, pongs and states, samples from another session or implausibly far ahead, forged
pongs, and commands not finite or outside the receiving port's range are dropped and counted; the
robot's bridge goes on delivering the operator's next good sample, and its clock offset stays put.
"""

from __future__ import annotations

import os
import socket
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hapticop.network import transport, wire
from hapticop.testing import BlockHarness

PATIENCE_S = 60.0  # a bound on hangs on a loaded machine, never a speed requirement
RANGE = (-10.0, 10.0)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Pair:
    """An operator's bridge sending `setpoint` (float64[3]) to a robot's bridge, both on virtual clocks
    stepped together about as fast as the wall clock, and an intruder: a third Zenoh peer."""

    def __init__(self, tmp_path: Path, hold: bool = False):
        self.system = f"refusals{os.getpid()}_{_free_port()}"
        operator_at, robot_at = f"tcp/127.0.0.1:{_free_port()}", f"tcp/127.0.0.1:{_free_port()}"
        setpoint = {"stream": "setpoint", "dtype": "float64", "shape": [3], "priority": "real_time"}
        common = {"system": self.system, "ping_period_ms": 20.0}
        self.operator = BlockHarness("zenoh_bridge", {
            **common, "host": "operator", "peers": ["robot"], "listen": [operator_at], "connect": [robot_at],
            "send": [setpoint], "import_flags": ["WHEEL_FAULT"],
            "hold_when_lost": ["WHEEL_FAULT"] if hold else []}, name="bridge", run_dir=tmp_path)
        self.robot = BlockHarness("zenoh_bridge", {
            **common, "host": "robot", "peers": ["operator"], "listen": [robot_at], "connect": [operator_at],
            "receive": [{**setpoint, "host": "operator", "range": list(RANGE)}], "export_flags": ["WHEEL_FAULT"]},
            name="bridge", run_dir=tmp_path)
        self.intruder = transport.session([f"tcp/127.0.0.1:{_free_port()}"], [robot_at])
        for harness in (self.operator, self.robot):
            harness.block.create()
            harness.block.configure_resources()
        ready = {"operator": False, "robot": False}
        deadline = time.monotonic() + PATIENCE_S
        while not all(ready.values()):
            assert time.monotonic() < deadline, f"the bridges did not link within {PATIENCE_S} s"
            for name, harness in (("operator", self.operator), ("robot", self.robot)):
                for port in vars(harness.inputs).values():  # what the runtime does before a step
                    port.refresh()
                if ready[name]:
                    harness.block.compute()  # answering the other's pings
                else:
                    ready[name] = harness.block.configure_capabilities()
                harness.advance()
            time.sleep(0.001)
        self.delivered: list[np.ndarray] = []
        self.seen = 0
        self.senders: dict[str, transport.Sender] = {}

    def close(self) -> None:
        self.intruder.close()
        for harness in (self.operator, self.robot):
            harness.clean()

    def step(self, send: list[float] | None = None, robot: bool = True) -> None:
        if send is not None:
            self.operator.feed("out_setpoint", send)
        self.operator.step()
        if robot:
            self.robot.step()
            port = self.robot.outputs.in_setpoint
            if port.published != self.seen:
                self.seen = port.published
                self.delivered.append(port.value.copy())
        time.sleep(0.001)

    def follows(self, value: list[float]) -> None:
        """The operator sends `value` each cycle until the robot's bridge delivers it."""
        deadline = time.monotonic() + PATIENCE_S
        while not self.delivered or not np.array_equal(self.delivered[-1], value):
            assert time.monotonic() < deadline, f"{value} not delivered within {PATIENCE_S} s"
            self.step(value)

    def put(self, key: str, payload: bytes) -> None:
        if key not in self.senders:
            self.senders[key] = transport.Sender(self.intruder, key)
        self.senders[key].put(payload)

    def refuse(self, key: str, payload: bytes, why: str) -> None:
        """The intruder puts `payload` on `key` (again, until it reaches the robot) and the robot refuses it."""
        before = self.refused(why)
        deadline = time.monotonic() + PATIENCE_S
        while self.refused(why) <= before:
            assert time.monotonic() < deadline, f"nothing refused as '{why}' within {PATIENCE_S} s"
            self.put(key, payload)
            for _ in range(5):
                self.step([0.1, 0.0, 0.0])

    @property
    def keys(self) -> dict[str, str]:
        """Every key the robot's bridge listens on."""
        return {"sample": wire.sample_key(self.system, "setpoint"), "ping": wire.ping_key(self.system, "operator"),
                "pong": wire.pong_key(self.system, "robot"), "state": wire.state_key(self.system, "operator")}

    @property
    def offset_ns(self) -> float:
        return self.robot.block.clocks["operator"].offset_ns

    def refused(self, why: str) -> int:
        refusals = self.robot.block.refusals["setpoint"].by_reason | self.robot.block.pong_refusals.by_reason
        return refusals.get(why, 0)

    def header(self, sequence_ahead: int = 1, sent: int | None = None, session: int | None = None) -> bytes:
        """A sample header as the operator's own bridge would write it (its session, its next sequence)."""
        block = self.operator.block
        return wire.SAMPLE.pack(block.session_id if session is None else session,
                                block.sequence["setpoint"] + sequence_ahead,
                                self.operator.clock.now_ns() if sent is None else sent)

    def wait_refused(self, why: str, before: int) -> None:
        deadline = time.monotonic() + PATIENCE_S
        while self.refused(why) <= before:
            assert time.monotonic() < deadline, f"nothing refused as '{why}' within {PATIENCE_S} s"
            self.step([0.1, 0.0, 0.0])

    def assert_safe(self) -> None:
        values = np.array(self.delivered)
        assert np.all(np.isfinite(values)) and np.all((values >= RANGE[0]) & (values <= RANGE[1])), values


@pytest.fixture
def pair(tmp_path):
    made = Pair(tmp_path)
    yield made
    made.close()


def test_malformed_samples_pongs_and_states_are_dropped_and_the_next_good_sample_delivered(pair):
    """The samples of issue 29 that once ended the bridge's activity: each is dropped and counted, and
    the operator's next sample is delivered."""
    pair.follows([0.1, 0.0, 0.0])
    value = np.array([0.3, 0.0, 0.0]).tobytes()
    cases = [("sample", b"\0" * 8, "malformed"), ("sample", b"", "malformed"),
             ("sample", pair.header() + value[:-8], "malformed"),
             ("sample", pair.header() + value + b"\0" * 25, "malformed"),
             ("sample", pair.header() + bytes(65536), "malformed"),
             ("sample", pair.header(sent=-(2**63)) + value, "implausible send time"),
             ("sample", pair.header(sent=2**63 - 1) + value, "implausible send time"),
             ("state", b"abc", "malformed state"),
             ("state", wire.STATE.pack(pair.operator.block.session_id, False) + b"\xff\xfe", "malformed state"),
             ("pong", b"\1\2\3", "malformed pong"),
             ("ping", b"\0" * 7, "malformed ping")]
    for n, (key, payload, why) in enumerate(cases):
        pair.refuse(pair.keys[key], payload, why)
        pair.follows([0.2 + n / 100, 0.0, 0.0])
    pair.assert_safe()
    for _ in range(30):  # the link's figures, `refused` among them, are published with each ping
        pair.step([0.1, 0.0, 0.0])
    assert pair.robot.outputs.refused.value >= len(cases)


@pytest.mark.parametrize("bad", [[1e300, 0.0, 0.0], [0.0, 0.0, np.inf], [np.nan, 0.0, 0.0], [0.0, 10.5, 0.0]])
def test_a_command_not_finite_or_out_of_range_is_refused_and_the_next_good_one_followed(pair, bad):
    """An authenticated but faulty operator: its own bridge sends the bad command; the robot's refuses it."""
    pair.follows([0.1, 0.0, 0.0])
    before = pair.refused("not finite or out of range")
    for _ in range(20):
        pair.step(bad)
    pair.wait_refused("not finite or out of range", before)
    pair.follows([0.25, 0.0, 0.0])
    pair.assert_safe()
    lines = pair.robot.log_lines()
    assert sum("refused a sample (not finite or out of range)" in line for line in lines) == 1, lines


def test_a_third_peer_cannot_take_the_stream_over(pair):
    """Samples 10^7 ahead, from a session of its own and then with the operator's own session: none is
    delivered, and the operator's samples are followed throughout and after (none turn 'old')."""
    pair.follows([0.2, 0.0, 0.0])
    start = pair.robot.clock.now_ns()
    hijack = np.array([-0.44, 0.0, 0.0]).tobytes()
    foreign, ahead = pair.refused("not from its owner's session"), pair.refused("implausibly far ahead")
    deadline = time.monotonic() + PATIENCE_S
    while pair.robot.clock.now_ns() - start < 1_500_000_000 or pair.refused("implausibly far ahead") <= ahead:
        assert time.monotonic() < deadline, f"no sample far ahead refused within {PATIENCE_S} s"
        pair.put(pair.keys["sample"], pair.header(10**7, session=12345) + hijack)
        pair.put(pair.keys["sample"], pair.header(10**7) + hijack)
        pair.step([0.2, 0.0, 0.0])
    assert pair.refused("not from its owner's session") > foreign
    assert all(v[0] == pytest.approx(0.2) for v in pair.delivered[-50:])
    assert not any(v[0] < 0 for v in pair.delivered)
    pair.follows([0.3, 0.0, 0.0])  # the operator's next samples are new, not 'old'


def test_forged_pongs_do_not_move_the_clock_offset(pair):
    """A peer that sees the robot's pings answers each one first, with the right slot, nonce and sessions,
    and times that put the operator's clock 10 s ahead: the offset stays where the true pongs put it."""
    pair.follows([0.1, 0.0, 0.0])
    offset = pair.offset_ns
    forged: list[bytes] = []

    def answer(sample) -> None:
        data = sample.payload.to_bytes()
        if len(data) == wire.PING.size:
            session, slot, nonce, t1 = wire.PING.unpack(data)
            skewed = t1 + 10_000_000_000
            forged.append(wire.PONG.pack(session, slot, nonce, t1, skewed, skewed, 0, pair.operator.block.session_id)
                          + b"operator")

    subscriber = pair.intruder.declare_subscriber(wire.ping_key(pair.system, "robot"), answer)
    try:
        before = pair.refused("pong contradicting the clock offset")
        deadline = time.monotonic() + PATIENCE_S
        while pair.refused("pong contradicting the clock offset") < before + 10:
            assert time.monotonic() < deadline, "no forged pong refused"
            while forged:
                pair.put(pair.keys["pong"], forged.pop())
            pair.step([0.1, 0.0, 0.0])
    finally:
        subscriber.undeclare()
    assert abs(pair.offset_ns - offset) < 50_000_000, (pair.offset_ns, offset)
    pair.refuse(pair.keys["pong"], wire.PONG.pack(1, 0, 0, 0, 0, 0, 0, 0) + b"operator", "pong to no ping of ours")
    pair.follows([0.2, 0.0, 0.0])


def test_a_pong_without_its_pings_nonce_is_refused(pair):
    """A pong right in every other way (session, slot, send time, plausible times) but for the nonce."""
    pair.follows([0.1, 0.0, 0.0])
    forged: list[bytes] = []

    def answer(sample) -> None:
        data = sample.payload.to_bytes()
        if len(data) == wire.PING.size:
            session, slot, nonce, t1 = wire.PING.unpack(data)
            forged.append(wire.PONG.pack(session, slot, nonce ^ 1, t1, t1, t1, 0, pair.operator.block.session_id)
                          + b"operator")

    subscriber = pair.intruder.declare_subscriber(wire.ping_key(pair.system, "robot"), answer)
    try:
        before = pair.refused("pong to no ping of ours")
        deadline = time.monotonic() + PATIENCE_S
        while pair.refused("pong to no ping of ours") < before + 5:
            assert time.monotonic() < deadline, "no pong without its nonce refused"
            while forged:
                pair.put(pair.keys["pong"], forged.pop())
            pair.step([0.1, 0.0, 0.0])
    finally:
        subscriber.undeclare()
    pair.follows([0.2, 0.0, 0.0])


def test_a_restarted_operator_is_a_new_session_announced_and_followed(pair, tmp_path):
    pair.follows([0.1, 0.0, 0.0])
    for _ in range(200):
        pair.step([0.1, 0.0, 0.0])  # its sequence numbers run well ahead of a restarted one's
    sessions, late = int(pair.robot.outputs.sessions.value), pair.refused("late or duplicate")
    old = pair.operator
    old.clean()
    pair.operator = BlockHarness("zenoh_bridge", old.params.model_dump(), name="bridge", run_dir=tmp_path)
    pair.operator.clock.advance_to(old.clock.now_ns())
    pair.operator.block.create()
    pair.operator.block.configure_resources()
    pair.follows([0.2, 0.0, 0.0])
    assert pair.refused("late or duplicate") == late  # the new session's first samples are not taken for old
    for _ in range(30):  # the link's figures are published with each ping
        pair.step([0.2, 0.0, 0.0])
    assert int(pair.robot.outputs.sessions.value) == sessions + 1
    assert any("started a new session" in line for line in pair.robot.log_lines())


def test_the_operators_side_holds_while_the_link_is_lost(tmp_path):
    """The robot goes silent: past `lost_after_ms` the operator's bridge raises the held place
    (WHEEL_FAULT: the haptic controller commands no motion) until the robot is heard again."""
    pair = Pair(tmp_path, hold=True)
    try:
        pair.follows([0.1, 0.0, 0.0])
        assert not pair.operator.flags["in_wheel_fault"]
        # The robot not stepped (not answering), one operator cycle (1 ms of its clock) at a time until it
        # says the link is lost: what the robot sent before it fell silent may still arrive late on a busy
        # machine, so how many cycles that takes is not fixed, only that it is never fewer than 250 ms' worth.
        silent = 0
        deadline = time.monotonic() + PATIENCE_S
        while not pair.operator.flags["link_lost"]:
            assert time.monotonic() < deadline, f"the link not lost after {silent} ms of the robot's silence"
            pair.step([0.1, 0.0, 0.0], robot=False)
            silent += 1
        assert silent >= 250  # lost_after_ms of the operator's clock, not sooner
        assert pair.operator.flags["in_wheel_fault"]
        deadline = time.monotonic() + PATIENCE_S
        while pair.operator.flags["in_wheel_fault"]:
            assert time.monotonic() < deadline, "the operator's side still held after the robot answered again"
            pair.step([0.1, 0.0, 0.0])
    finally:
        pair.close()


FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def fuzzed(tmp_path_factory):
    made = Pair(tmp_path_factory.mktemp("fuzz"))
    made.follows([0.1, 0.0, 0.0])
    for key, why in (("sample", "malformed"), ("ping", "malformed ping"), ("pong", "malformed pong"),
                     ("state", "malformed state")):  # every key's route known before the first example
        made.refuse(made.keys[key], b"\1\2\3", why)
    yield made
    made.close()


@FUZZ
@given(key=st.sampled_from(["sample", "ping", "pong", "state"]), headed=st.booleans(),
       payload=st.binary(max_size=200), step=st.integers(1, 1_000))
def test_arbitrary_bytes_on_every_key_never_break_the_bridge(fuzzed, key, headed, payload, step):
    """Whatever arrives on a key the robot's bridge listens on (raw, or behind a true header of the operator's
    session, to reach past the first checks): no exception, nothing non-finite or out of range delivered, the
    clock offset unmoved, and the operator's next sample delivered."""
    if headed:
        session = struct.pack("<Q", fuzzed.operator.block.session_id)
        payload = (fuzzed.header() if key == "sample" else session) + payload
    offset = fuzzed.offset_ns
    fuzzed.put(fuzzed.keys[key], payload)
    for _ in range(3):
        fuzzed.step([0.1, 0.0, 0.0])
    fuzzed.follows([step / 1000, 0.0, 0.0])
    fuzzed.assert_safe()
    assert abs(fuzzed.offset_ns - offset) < 50_000_000


def test_a_faulty_operator_moves_the_robot_by_nothing_beyond_its_own_limits(pair):
    """End to end: the operator's bridge sends 1e300, infinity and NaN between good setpoints; the robot's
    bridge delivers what it accepts to the platform controller (its robot-side limits as in
    systems/hallway.yaml), which executes nothing beyond them and follows each good setpoint again."""
    from tests.test_ropod_controller import _ropod

    ropod = _ropod()
    limit, step_limit = np.array([1.5, 1.0, 1.6]), np.array([100.0, 100.0, 200.0]) * 1e-3
    seen = pair.seen

    def cycle(value: list[float]) -> None:
        nonlocal seen
        pair.step(value)
        if pair.seen != seen:
            seen = pair.seen
            ropod.feed("velocity_setpoint", pair.delivered[-1])
        before = ropod.block.controller.v_sp
        ropod.step()
        executed = ropod.block.controller.v_sp
        assert np.all(np.abs(executed) <= limit) and np.all(np.abs(executed - before) <= step_limit + 1e-12)

    for bad in ([1e300, 0.0, 0.0], [0.0, 0.0, np.inf], [np.nan, 0.0, 0.0]):
        for _ in range(100):
            cycle([0.4, 0.0, 0.2])
        for _ in range(100):
            cycle(bad)
        deadline = time.monotonic() + PATIENCE_S
        while not np.allclose(ropod.block.controller.v_sp, [0.3, 0.0, -0.2]):
            assert time.monotonic() < deadline, "the robot did not follow the good setpoint again"
            cycle([0.3, 0.0, -0.2])
    pair.assert_safe()


def test_a_stream_without_a_range_is_taken_as_it_is_infinities_included():
    """A scan says 'no return' with an infinity: only a port that declares a range is checked, so the
    operator's side is never blinded by its own robot's scans (two hosts, systems/teleop.yaml)."""
    from hapticop.blocks.bounds import Bounds
    from hapticop.blocks.interface import Port

    scan = Bounds(Port("float32", (4,), "m"), "stream 'scan_ranges'")
    assert not scan.checks and scan.admits(np.array([np.inf, 1.0, np.inf, 0.5], np.float32))
    command = Bounds(Port("float64", (3,), range=(-10.0, 10.0)), "stream 'velocity_setpoint'")
    assert command.checks and not command.admits(np.array([np.inf, 0.0, 0.0]))


@pytest.mark.parametrize("length", [3, 16, 17, 811])  # checked as floats up to bounds.SHORT, by ufuncs beyond
def test_a_range_check_refuses_a_sample_with_any_element_bad_and_admits_its_edges(length):
    from hapticop.blocks.bounds import SHORT, Bounds
    from hapticop.blocks.interface import Port

    assert (length <= SHORT) == (length in (3, 16))
    bounds = Bounds(Port("float64", (length,), range=(-2.0, 5.0)), "stream 'command'")
    edges = np.linspace(-2.0, 5.0, length)
    assert bounds.admits(edges) and bounds.admits(np.full(length, -2.0)) and bounds.admits(np.full(length, 5.0))
    refused = 0
    for where in sorted({0, length // 2, length - 1}):
        for bad in (np.nan, np.inf, -np.inf, -2.0000000000000004, 5.000000000000001, 1e300):
            sample = edges.copy()
            sample[where] = bad
            assert not bounds.admits(sample), (where, bad)
            refused += 1
    assert bounds.refused == bounds.burst == refused
