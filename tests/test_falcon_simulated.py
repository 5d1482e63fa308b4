"""The simulated Falcon in closed loop with a host written the way the Falcon block will be."""

from __future__ import annotations

import numpy as np
import pytest

from hapticop.devices.falcon import (
    Button,
    FalconKinematics,
    Flag,
    FrameCodec,
    Homing,
    SimulatedFalcon,
    Status,
    new_frame,
)
from hapticop.testing import grown_bytes

DT = 0.001
CENTRE = np.array([0.0, 0.0, 0.125])


class Operator:
    """A hand on the grip: a stiff spring-damper pulling the handle toward a target."""

    def __init__(self, sim: SimulatedFalcon, k: float = 300.0, c: float = 30.0) -> None:
        self.sim, self.k, self.c = sim, k, c

    def force(self, target) -> np.ndarray:
        return self.k * (np.asarray(target, float) - self.sim.position) - self.c * self.sim.velocity


class Host:
    """The block's side: codec, homing, FK, a force law, forces_to_motor; one exchange per ms."""

    def __init__(self, sim: SimulatedFalcon) -> None:
        self.sim, self.codec, self.kin = sim, FrameCodec(), FalconKinematics()
        self.homing, self.status = Homing(), Status()
        self.cmd, self.reply = new_frame(), new_frame()
        self.position, self.motor = np.full(3, np.nan), np.zeros(3, dtype=np.int64)
        self.fk_ok = False

    def cycle(self, force_law=None, external=(0.0, 0.0, 0.0), homing: bool = True) -> None:
        flags = self.homing.command_flags() if homing else Flag.LED_RED
        self.codec.encode_command(self.motor, flags, self.cmd)
        assert self.sim.exchange(self.cmd, DT, external, out=self.reply) is self.reply
        self.codec.decode_status(self.reply, self.status)
        self.homing.update(self.status)
        if self.homing.just_homed:
            self.kin.reset()  # the counts just jumped to absolute
        self.fk_ok = self.kin.forward(self.status.encoders, self.position)
        self.motor[:] = 0
        if force_law is not None and self.homing.forces_allowed and self.fk_ok:
            self.kin.forces_to_motor(None, force_law(self.position), self.motor)


def home(host: Host, operator: Operator) -> int:
    """Pull the grip out, push it in (docs/devices/falcon.md §6); returns the cycle it homed at."""
    for i in range(2500):
        target = (0.0, 0.0, 0.178) if i < 800 else (0.0, 0.0, 0.075)
        host.cycle(external=operator.force(target))
        if host.homing.homed:
            return i
    raise AssertionError(f"not homed, flags {host.homing.mask:03b}")


@pytest.fixture
def rig():
    sim = SimulatedFalcon(rng=np.random.default_rng(3))
    return sim, Host(sim), Operator(sim)


def test_counts_are_relative_until_homed(rig):
    sim, host, _ = rig
    host.cycle()
    assert host.status.encoders.tolist() == [0, 0, 0]  # power-on pose reads zero
    assert not host.status.homed.any() and not host.homing.forces_allowed
    assert np.abs(host.position - sim.position).max() > 1e-3  # so FK says nothing true yet
    assert sim.leds == Flag.LED_RED


def test_homing_needs_the_bit_and_the_out_in_motion(rig):
    sim, host, operator = rig
    for i in range(1800):  # the motion alone, without the homing bit
        host.cycle(external=operator.force((0, 0, 0.178) if i < 800 else (0, 0, 0.075)), homing=False)
    assert not sim.homed.any() and host.status.homed_mask == 0
    for _ in range(600):  # the bit alone, grip held in
        host.cycle(external=operator.force((0, 0, 0.075)))
    assert not sim.homed.any()
    at = home(host, operator)
    assert host.homing.homed and host.status.all_homed and sim.leds == Flag.LED_RED  # green next frame
    host.cycle(external=operator.force((0, 0, 0.075)))
    assert sim.leds == Flag.LED_GREEN and not host.homing.just_homed
    assert at > 800  # only on the way in
    # absolute now: FK of the reported counts is the true handle position, to a count
    assert host.fk_ok and np.abs(host.position - sim.position).max() < 5e-5
    # flags are reported only while the bit is set; the counts stay absolute
    host.cycle(external=operator.force((0, 0, 0.075)), homing=False)
    assert host.status.homed_mask == 0 and not host.homing.homed and host.homing.lost == 1
    assert np.abs(host.position - sim.position).max() < 5e-5


def test_axes_home_one_by_one(rig):
    sim, host, operator = rig
    for _ in range(800):
        host.cycle(external=operator.force((0.0, 0.0, 0.178)))
    seen = set()
    for i in range(1500):  # push in along a slant so the legs pass their references apart
        host.cycle(external=operator.force((0.015, 0.0, 0.072)))
        seen.add(host.homing.mask)
        if host.homing.homed:
            break
    assert host.homing.homed and len(seen) > 2 and host.homing.missing_axes() == ()


def test_zero_force_leaves_the_handle_where_the_operator_put_it(rig):
    sim, host, operator = rig
    home(host, operator)
    zero = lambda p: np.zeros(3)  # noqa: E731
    target = (0.02, -0.015, 0.14)
    for _ in range(600):
        host.cycle(zero, external=operator.force(target))
    assert np.abs(sim.position - target).max() < 1e-3  # nothing resisted the push
    for _ in range(1500):  # let go: it coasts to a stop, nothing pulls it back
        host.cycle(zero)
    rest = sim.position
    for _ in range(1000):
        host.cycle(zero)
    assert np.abs(sim.position - rest).max() < 1e-5
    assert np.abs(rest - target).max() < 2e-3
    assert np.abs(host.position - rest).max() < 1e-4 and host.motor.tolist() == [0, 0, 0]


def test_spring_pulls_the_handle_back_to_the_origin(rig):
    sim, host, operator = rig
    home(host, operator)
    kp, kd, previous = 200.0, 5.0, np.zeros(3)

    def spring(p: np.ndarray) -> np.ndarray:
        nonlocal previous
        velocity = (p - previous) / DT
        previous = p.copy()
        return -kp * (p - CENTRE) - kd * velocity

    for _ in range(500):  # the operator holds it 25 mm off centre against the spring
        host.cycle(spring, external=operator.force((0.02, -0.015, 0.14)))
    start = np.linalg.norm(sim.position - CENTRE)
    assert start > 0.01 and np.abs(host.motor).max() > 500
    distance = []
    for _ in range(2000):  # let go: 2 s at 1 kHz
        host.cycle(spring)
        distance.append(np.linalg.norm(sim.position - CENTRE))
    assert distance[-1] < 1e-3
    assert max(distance) <= start + 1e-4  # stable: never further out than where it was let go
    assert max(distance[-300:]) < 1e-3


def test_same_seed_same_bytes_and_the_seed_matters():
    def run(seed):
        sim, out = SimulatedFalcon(rng=seed), []
        cmd = new_frame()
        FrameCodec().encode_command([300, -200, 100], Flag.HOMING, cmd)
        for i in range(200):
            out.append(sim.exchange(cmd, DT, (0.0, 0.0, 2.0 if i < 100 else -2.0)))
        return out

    assert run(7) == run(7)
    assert run(7) != run(8)


def test_malformed_commands_get_no_reply_but_time_passes():
    sim = SimulatedFalcon(rng=1)
    assert sim.exchange(b"<AAAAAAAAAAAAAA", DT) is None
    assert sim.exchange(b"<AAAAAAAAAAAABA<", DT) is None
    assert sim.malformed == 2 and sim.time_s == pytest.approx(2 * DT) and sim.frames_out == 0
    reply = sim.exchange(b"<AAAAAAAAAAAABA>", DT)
    status = FrameCodec().decode_status(reply, Status())
    assert isinstance(reply, bytes) and sim.frames_out == 1 and status.spare == 0


def test_motor_commands_saturate_and_expire_after_100_ms():
    sim = SimulatedFalcon(rng=1, damping=50.0)
    cmd = new_frame()
    FrameCodec().encode_command([40000, 0, 1000], 0, cmd, limit=None)  # 40000 wraps to -25536
    sim.exchange(cmd, DT)
    assert sim.motor.tolist() == [-4095, 0, 1000]
    sim.step(0.098)
    assert sim.motor.tolist() == [-4095, 0, 1000]
    moved = sim.velocity
    sim.step(0.005)
    assert sim.motor.tolist() == [0, 0, 0]
    sim.step(0.5)  # no force left: damping stops the handle
    assert np.abs(sim.velocity).max() < 1e-3 * max(np.abs(moved).max(), 1e-9) + 1e-9


def test_buttons_and_leds_are_observable():
    sim = SimulatedFalcon(rng=1, homed=True)
    sim.buttons = Button.CENTRE | Button.PLUS
    cmd = new_frame()
    FrameCodec().encode_command([0, 0, 0], Flag.HOMING | Flag.LED_BLUE, cmd)
    status = FrameCodec().decode_status(sim.exchange(cmd, DT), Status())
    assert status.buttons == Button.CENTRE | Button.PLUS and status.all_homed
    assert sim.leds == Flag.LED_BLUE


def test_end_stops_keep_the_handle_in_the_workspace():
    sim = SimulatedFalcon(rng=1)
    kin, theta = FalconKinematics(), np.zeros(3)
    cmd = new_frame()
    FrameCodec().encode_command([0, 0, 0], 0, cmd)
    for _ in range(1000):
        sim.exchange(cmd, DT, (0.0, 0.0, 40.0))
    assert kin.inverse(sim.position, theta) and sim.position[2] > 0.17


def test_an_unreachable_start_is_refused():
    with pytest.raises(ValueError):
        SimulatedFalcon(initial_position=(0.0, 0.0, 0.3))


def test_exchange_into_out_allocates_nothing_that_stays():

    sim, cmd, reply = SimulatedFalcon(rng=1, homed=True), new_frame(), new_frame()
    force = np.array([0.0, 0.0, 1.0])
    FrameCodec().encode_command([100, -100, 50], Flag.HOMING, cmd)

    def cycles(n):
        for i in range(n):
            force[2] = 1.0 if (i // 200) % 2 else -1.0
            sim.exchange(cmd, DT, force, out=reply)

    cycles(300)
    grown = grown_bytes(lambda: cycles(3000))
    assert grown < 2048


def test_one_step_is_the_equation_of_motion():
    """m dv = (M^T tau + F_operator - c v) h with tau = command / -10000, then p += v h (semi-implicit Euler)."""
    sim, kin, codec = SimulatedFalcon(rng=2, damping=3.0, handle_mass_kg=0.7), FalconKinematics(), FrameCodec()
    cmd, rng = new_frame(), np.random.default_rng(5)
    for _ in range(20):
        command, push = rng.integers(-3000, 3000, 3), rng.normal(size=3)
        codec.encode_command(command, 0, cmd)
        p0, v0, F = sim.position, sim.velocity, np.zeros(3)
        assert kin.torques_to_force(p0, command / -10000.0, F)
        sim.exchange(cmd, DT, push)
        v1 = v0 + (F + push - 3.0 * v0) * DT / 0.7
        assert sim.velocity == pytest.approx(v1, rel=1e-12, abs=1e-15)
        assert sim.position == pytest.approx(p0 + v1 * DT, rel=1e-12, abs=1e-15)
    position, velocity = np.zeros(3), np.zeros(3)
    sim.copy_state(position, velocity)
    assert position.tolist() == sim.position.tolist() and velocity.tolist() == sim.velocity.tolist()
