"""Test-only blocks, named in test compositions as 'tests.blocks:Name'."""

from __future__ import annotations

import gc
import os
import threading
import time
from typing import Literal

import numpy as np
from pydantic import Field

from hapticop.blocks.base import Block
from hapticop.blocks.interface import Params, Port


class StuckParams(Params):
    stuck_in: Literal["creation", "resource_configuration", "capability_configuration", "running"] = "running"


class Stuck(Block):
    """Never completes the configuration step it is told to be stuck in."""

    Params = StuckParams

    def create(self):
        return self._step("creation")

    def configure_resources(self):
        return self._step("resource_configuration")

    def configure_capabilities(self):
        return self._step("capability_configuration")

    def _step(self, stage: str) -> bool:
        stuck = self.params.stuck_in == stage
        self.context.waiting_for(f"a '{stage}' that never completes (a test)" if stuck else None)
        return not stuck

    def clean(self):
        (self.run_dir / f"{self.name}.cleaned").write_text("yes")


class NoiseParams(Params):
    sigma: float = Field(1.0, ge=0)


class Noise(Block):
    """Publishes seeded Gaussian noise: tests that a seed reproduces a run bit for bit."""

    Params = NoiseParams
    outputs = {"sample": Port("float64", (3,), "1")}

    def compute(self):
        self.outputs.sample.value[:] = self.rng.normal(0.0, self.params.sigma, 3)
        self.outputs.sample.publish()


class RecorderParams(Params):
    capacity: int = Field(100_000, ge=1)


class Recorder(Block):
    """Keeps every new input sample with its stamp; writes them to the run directory on clean."""

    Params = RecorderParams
    inputs = {"sample": Port("float64", (3,), "1")}

    def create(self):
        self.samples = np.zeros((self.params.capacity, 3))
        self.stamps = np.zeros(self.params.capacity, dtype=np.int64)
        self.n = 0

    def compute(self):
        port = self.inputs.sample
        if port.fresh and self.n < len(self.samples):
            self.samples[self.n] = port.value
            self.stamps[self.n] = port.stamp_ns
            self.n += 1

    def clean(self):
        np.savez(self.run_dir / f"{self.name}.npz", samples=self.samples[: self.n], stamps=self.stamps[: self.n])


class Tally(Block):
    """Counts its computes and writes the count on clean: what the timing's 'steps' must match."""

    def create(self):
        self.computes = 0

    def compute(self):
        self.computes += 1

    def clean(self):
        (self.run_dir / f"{self.name}.computes").write_text(str(self.computes))


class ConstantTwistParams(Params):
    twist: tuple[float, float, float] = (0.0, 0.0, 0.0)


class ConstantTwist(Block):
    """Commands a constant platform twist, or none while `held` (as the haptic controller does)."""

    Params = ConstantTwistParams
    outputs = {"velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s")}
    flags_read = {"held": "command no motion"}
    changes: list[bool] = []  # every change of `held` seen, for a test in this process to read

    def create(self):
        self.held = False

    def compute(self):
        held = bool(self.flags["held"])
        if held != self.held:
            self.held = held
            ConstantTwist.changes.append(held)
        out = self.outputs.velocity_setpoint
        out.value[:] = 0.0 if held else self.params.twist
        out.publish()


class HeldHandleParams(Params):
    push_m: tuple[float, float, float] = (0.0, 0.0, 0.0)


class HeldHandle(Block):
    """Stands for the Falcon's handle: at its origin until `go`, then held at `push_m` (a hand
    that pushes and keeps pushing), so the real haptic controller drives."""

    Params = HeldHandleParams
    outputs = {"position": Port("float64", (3,), "m"), "velocity": Port("float64", (3,), "m/s")}
    flags_read = {"go": "the haptic loop runs: push"}

    def compute(self):
        self.outputs.position.value[:] = self.params.push_m if self.flags["go"] else 0.0
        self.outputs.velocity.value[:] = 0.0
        self.outputs.position.publish()
        self.outputs.velocity.publish()


class OpenScan(Block):
    """Stands for the LIDAR in open space: every beam of the TiM561's 270 degrees sees nothing
    within 20 m, a fresh scan every cycle."""

    outputs = {"ranges": Port("float32", (811,), "m"), "angles": Port("float32", (811,), "rad")}

    def create(self):
        self.outputs.angles.value[:] = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 811)
        self.outputs.ranges.value[:] = 20.0

    def compute(self):
        self.outputs.angles.publish()
        self.outputs.ranges.publish()


class SetpointWatch(Block):
    """Reads a velocity setpoint and keeps, in this process, every change between zero and motion."""

    inputs = {"velocity_setpoint": Port("float64", (3,), "m/s, m/s, rad/s")}
    zero_changes: list[bool] = []  # True: the setpoint became zero; False: it commands motion again

    def create(self):
        self.zero = True

    def compute(self):
        port = self.inputs.velocity_setpoint
        if port.valid:
            zero = not port.value.any()
            if zero != self.zero:
                self.zero = zero
                SetpointWatch.zero_changes.append(zero)


class Simulator(Block):
    """Stands for a simulated device: it does some arithmetic each cycle, all of it simulation."""

    simulator = True

    def create(self):
        self.state = np.zeros(256)

    def compute(self):
        np.sin(self.state, out=self.state)
        self.state += 0.001


class LoopbackParams(Params):
    fail_after: int = Field(0, ge=0, description="raise in flush after this many cycles; 0 never")


class Loopback(Block):
    """A device read in compute and written in flush: it counts cycles out and keeps, for every
    cycle, what came back to be written in that cycle's flush."""

    Params = LoopbackParams
    inputs = {"command": Port("float64", (), "1")}
    outputs = {"reading": Port("float64", (), "1")}

    def create(self):
        self.cycle = 0
        self.written = np.full(10_000, np.nan)

    def compute(self):
        self.cycle += 1
        self.outputs.reading.value[...] = self.cycle
        self.outputs.reading.publish()

    def flush(self):
        if self.params.fail_after and self.cycle > self.params.fail_after:
            raise RuntimeError("the device refused the write")
        if self.cycle < len(self.written):
            self.written[self.cycle] = self.inputs.command.value

    def clean(self):
        np.save(self.run_dir / f"{self.name}.npy", self.written[1 : self.cycle + 1])


class PingPong(Block):
    """A device that sends a byte whenever the block has answered the last one (a thread on the
    far end of a socket pair): the number of round trips shows how fast data wakes the thread."""

    def configure_resources(self):
        import socket
        import threading

        self.host, device = socket.socketpair()
        self.host.setblocking(False)
        self.round_trips = 0

        def run():
            with device:
                device.settimeout(5.0)
                try:
                    while device.send(b"?") and device.recv(1):
                        pass
                except OSError:
                    pass  # the host closed its end: the device is unplugged

        threading.Thread(target=run, daemon=True).start()
        return True

    def wakeup_fds(self):
        return (self.host.fileno(),)

    def compute(self):
        try:
            if self.host.recv(1):
                self.round_trips += 1
                self.host.send(b"!")
        except BlockingIOError:
            pass

    def clean(self):
        self.host.close()
        (self.run_dir / f"{self.name}.round_trips").write_text(str(self.round_trips))


class SpringParams(Params):
    stiffness_n_per_m: float = 50.0


class Spring(Block):
    """Centres a Falcon's handle with a spring: a haptic controller without a LIDAR."""

    Params = SpringParams
    inputs = {"position": Port("float64", (3,), "m")}
    outputs = {"force": Port("float64", (3,), "N")}

    def compute(self):
        np.multiply(self.inputs.position.value, -self.params.stiffness_n_per_m, out=self.outputs.force.value)
        self.outputs.force.publish()


class SwitchParams(Params):
    on_at: int = Field(100, ge=0, description="cycle at which the flag goes true")
    off_at: int = Field(200, ge=0, description="cycle at which it goes false again")


class Switch(Block):
    """Holds its flag 'on' true from cycle on_at to off_at: a grip held, then let go."""

    Params = SwitchParams
    flags_written = {"on": "true between on_at and off_at"}

    def create(self):
        self.cycle = 0

    def compute(self):
        self.cycle += 1
        self.flags["on"] = self.params.on_at <= self.cycle < self.params.off_at


class GainParams(Params):
    gain: float = Field(1.0, description="published every cycle")
    label: str = Field("", description="a parameter that needs re-configuration")


class Gain(Block):
    """Publishes its running parameter `gain` each cycle and keeps every value it published."""

    Params = GainParams
    outputs = {"gain": Port("float64", (), "1")}
    running_params = frozenset({"gain"})

    def create(self):
        self.seen = []
        self.retuned = []

    def retune(self, changed):
        self.retuned.append(sorted(changed))

    def compute(self):
        self.seen.append(self.params.gain)
        self.outputs.gain.value[...] = self.params.gain
        self.outputs.gain.publish()

    def clean(self):
        (self.run_dir / f"{self.name}.gains").write_text(" ".join(f"{g:g}" for g in self.seen))
        (self.run_dir / f"{self.name}.retuned").write_text(repr(self.retuned))


class WhatItRunsWith(Block):
    """Writes, once it runs, where it runs and what the garbage collector's permanent generation
    holds (gc.freeze), for a test to read from outside the process."""

    def create(self):
        self.told = False

    def compute(self):
        if not self.told:
            self.told = True
            told = self.run_dir / f"{self.name}.runs"
            told.with_suffix(".part").write_text(f"{os.getpid()} {threading.get_native_id()} {gc.get_freeze_count()}")
            told.with_suffix(".part").rename(told)  # whole, or not there


class SameName(Block):
    """Declares 'force' both in and out: a stream could not tell them apart."""

    inputs = {"force": Port("float64", (3,), "N")}
    outputs = {"force": Port("float64", (3,), "N")}


class BadDeclaration(Block):
    """Its ports cannot be worked out: an author's bug."""

    @classmethod
    def interface(cls, params):
        raise ZeroDivisionError("division by zero")


class AgeProbeParams(Params):
    capacity: int = Field(200_000, ge=1)


class AgeProbe(Block):
    """Reads a sample each cycle; keeps each new sample's age on arrival and every cycle's validity
    (the stream's max_age) beside the age it was judged by, and writes them to the run directory on clean.

    The port judges validity at the step's start; the clock read inside `compute` is later by however
    long the thread waited for a core, so the deadman is checked against the port's own age."""

    Params = AgeProbeParams
    inputs = {"sample": Port("float64", (3,), "1")}

    def create(self):
        n = self.params.capacity
        self.arrived = np.zeros((n, 2), dtype=np.int64)  # [now, stamp] of each new sample
        self.cycles = np.zeros((n, 4), dtype=np.int64)  # [now, valid, stamp, age at the step's start] each cycle
        self.n_arrived = self.n_cycles = 0

    def compute(self):
        port, now = self.inputs.sample, self.clock.now_ns()
        if port.fresh and self.n_arrived < len(self.arrived):
            self.arrived[self.n_arrived] = (now, port.stamp_ns)
            self.n_arrived += 1
        if self.n_cycles < len(self.cycles):
            self.cycles[self.n_cycles] = (now, port.valid, port.stamp_ns, port.age_ns())
            self.n_cycles += 1

    def clean(self):
        np.savez(self.run_dir / f"{self.name}.npz", arrived=self.arrived[: self.n_arrived],
                 cycles=self.cycles[: self.n_cycles])


class Unbuildable(Block):
    """A block whose activity cannot be built: its constructor raises (a device that is not there)."""

    outputs = {"value": Port("float64", (), "1")}

    def __init__(self, context):
        raise OSError("the device is not there")


class SlowSumParams(Params):
    every: int = Field(20, ge=1, description="every Nth cycle is slow")
    sleep_ms: float = Field(5.0, ge=0, description="how long a slow cycle sleeps between reading and publishing")


class SlowSum(Block):
    """Sums the samples it sees, one a cycle, counting only those its input says are `valid`; every Nth
    cycle sleeps before looking, so its thread overruns and misses cycles while the input's writer
    goes on: on the wall clock, what a cycle saw is known only from what the run recorded of it."""

    Params = SlowSumParams
    inputs = {"value": Port("int64", (), "1")}
    outputs = {"total": Port("int64", (3,), "1", "[the sum of the valid samples seen, cycles run, valid now]")}

    def create(self):
        self.cycles = 0
        self.total = 0

    def compute(self):
        self.cycles += 1
        if self.cycles % self.params.every == 0:
            time.sleep(self.params.sleep_ms / 1e3)
        valid = self.inputs.value.valid  # as old as when the step began, however long it slept
        self.total += int(self.inputs.value.value) if valid else 0
        self.outputs.total.value[:] = (self.total, self.cycles, valid)
        self.outputs.total.publish()


class SlowCleanParams(Params):
    clean_s: float = Field(0.3, ge=0, description="how long cleaning takes, on its thread")


class SlowClean(Block):
    """Takes `clean_s` to clean, holding its thread: a shutdown that overruns its loop's periods."""

    Params = SlowCleanParams

    def clean(self):
        time.sleep(self.params.clean_s)
