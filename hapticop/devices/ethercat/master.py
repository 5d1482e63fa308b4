"""An EtherCAT master over pysoem (SOEM): bring-up, cyclic exchange, shutdown.

Bring-up is SOEM's: open the interface, `config_init` (find and name the slaves from
their SII), check them against the expected list by product code and order, `config_map`
(build the IOmap, program SMs and FMMUs), SAFE-OP, then OP while exchanging process data
so the outputs are valid before any drive is enabled. A slave whose SII offers CoE has its
PDO assignment (0x1C12/0x1C13 and the mapping objects they name) read over SDO in PRE-OP
and checked against the layout the driver expects. When slaves offer distributed clocks,
`config_dc` measures them before the mapping, and each slave that runs on SYNC0 (the smart
wheels, like ropod's own bring-up) gets SYNC0 at the fieldbus cycle from the PRE-OP ->
SAFE-OP hook, which SOEM runs again when it reconfigures a slave after a fault. The exchange moves raw images:
outputs are length-checked before they are written (pysoem's setter copies without
checking, and would run into the next slave's outputs). `always_release_gil` is set so
the other threads of the process run while SOEM waits on the wire; `config_map`,
`read_state`, `state_check`, `reconfig` and `recover` still hold the GIL.
Masters opened here are found by interface, so the watchdog of the same process can act on
the same SOEM context, as SOEM's own check thread does.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["ExpectedSlave", "SoemMaster", "SoemLink", "BringUpError", "find_master", "AL_OP", "AL_SAFEOP", "AL_INIT",
           "state_name"]

AL_NONE, AL_INIT, AL_PREOP, AL_BOOT, AL_SAFEOP, AL_OP, AL_ERROR = 0x00, 0x01, 0x02, 0x03, 0x04, 0x08, 0x10
_NAMES = {AL_NONE: "NONE", AL_INIT: "INIT", AL_PREOP: "PRE-OP", AL_BOOT: "BOOT", AL_SAFEOP: "SAFE-OP", AL_OP: "OP"}


def state_name(state: int) -> str:
    base = _NAMES.get(state & 0x0F, f"0x{state & 0x0F:02X}")
    return base + ("+ERR" if state & AL_ERROR else "")


class BringUpError(RuntimeError):
    """The segment could not be brought up; the message says which step and which slave."""


@dataclass(frozen=True)
class ExpectedSlave:
    name: str  # hapticop's name for it (for messages)
    product: int
    output_bytes: int = 0
    input_bytes: int = 0
    output_bits: tuple[int, ...] = ()  # bit length of each mapped output entry, in order (checked over CoE)
    input_bits: tuple[int, ...] = ()
    sync0: bool = False  # runs on SYNC0: configured at the master's cycle when the segment has DC


MBX_PROTOCOLS_WORD, MBX_COE = 0x1C, 0x0004  # SII word of the mailbox protocols; the CoE bit
SM_OUTPUTS, SM_INPUTS = 3, 4  # 0x1C00 sync-manager communication types


_masters: dict[str, SoemMaster] = {}
_lock = threading.Lock()


def find_master(interface: str) -> SoemMaster | None:
    """The master open on `interface` in this process, if any."""
    return _masters.get(interface)


class SoemMaster:
    def __init__(self, interface: str, expected: Sequence[ExpectedSlave], receive_timeout_us: int = 2000,
                 state_timeout_s: float = 2.0, frame_timeout_us: int | None = None, cycle_ns: int = 1_000_000,
                 mailbox_timeout_us: int | None = None):
        import pysoem

        self.pysoem = pysoem
        pysoem.settings.always_release_gil = True
        if frame_timeout_us is not None:  # SOEM's EC_TIMEOUTRET: how long a configuration datagram may take
            pysoem.settings.timeouts.ret = frame_timeout_us
        if mailbox_timeout_us is not None:  # SOEM's EC_TIMEOUTRXM: how long a slave may take to answer over CoE
            pysoem.settings.timeouts.rx_mailbox = mailbox_timeout_us
        self.interface = interface
        self.expected = list(expected)
        self.receive_timeout_us = receive_timeout_us
        self.state_timeout_s = state_timeout_s
        self.cycle_ns = cycle_ns  # SYNC0 cycle: the cycle the process data is exchanged at
        self.distributed_clocks = False
        self.coe_checked: list[str] = []  # the slaves whose PDO assignment was read over CoE
        self.sync0: list[str] = []  # the slaves given SYNC0
        self.master = pysoem.Master()
        self.slaves: list = []
        self.expected_wkc = 0
        # SOEM lets a check thread work beside the exchange (its port has its own locks), so the
        # exchange takes no lock; this one keeps the watchdog's recovery and close apart.
        self.lock = threading.Lock()
        self.opened = False
        self.last_wkc = 0
        self.up = False  # in OP once: the watchdog may act on it

    # --- bring-up ------------------------------------------------------------------------
    def open(self) -> None:
        with _lock:
            if self.interface in _masters:
                raise BringUpError(f"a master is already open on '{self.interface}' in this process")
            try:
                self.master.open(self.interface)
            except ConnectionError as error:
                raise BringUpError(f"cannot open EtherCAT interface '{self.interface}': {error} "
                                   "(does it exist, and is this process root?)") from None
            _masters[self.interface] = self
            self.opened = True

    def bring_up(self, on_safeop=None) -> None:
        """Up to OP, or BringUpError naming the step. `on_safeop()` writes safe outputs."""
        found = self.master.config_init()
        if found <= 0:  # SOEM returns -1, not 0, when nothing answers
            raise BringUpError(f"no EtherCAT slave answers on '{self.interface}'")
        self.slaves = list(self.master.slaves)
        self._check_slaves()
        if self.master.state_check(AL_PREOP, 50_000) != AL_PREOP:  # the mailboxes answer from PRE-OP on
            self.master.read_state()
            raise BringUpError("not every slave reached PRE-OP: " + self.describe_states())
        self._check_coe_layouts()
        self._configure_clocks()
        try:
            self.master.config_map()
        except self.pysoem.ConfigMapError as error:
            raise BringUpError(f"mapping the process data failed: {error}") from None
        self.expected_wkc = self.master.expected_wkc
        for slave, spec in zip(self.slaves, self.expected):
            if len(slave.output) != spec.output_bytes or len(slave.input) != spec.input_bytes:
                raise BringUpError(f"slave {spec.name} ({slave.name}) maps {len(slave.output)} output and "
                                   f"{len(slave.input)} input bytes; expected {spec.output_bytes} and "
                                   f"{spec.input_bytes}")
        if self.master.state_check(AL_SAFEOP, 50_000) != AL_SAFEOP:
            self.master.read_state()
            raise BringUpError("not every slave reached SAFE-OP: " + self.describe_states())
        if on_safeop is not None:
            on_safeop()
        self.master.state = AL_OP
        self.exchange()  # valid outputs before the request, as SOEM's examples do
        self.master.write_state()

        deadline = time.monotonic() + self.state_timeout_s
        while time.monotonic() < deadline:
            self.exchange()
            if self.master.state_check(AL_OP, 1000) == AL_OP:
                self.up = True
                return
        self.master.read_state()
        raise BringUpError("not every slave reached OP: " + self.describe_states())

    # --- CoE: the PDO assignment the slave reports ----------------------------------------
    def _check_coe_layouts(self) -> None:
        """Each slave offering CoE: its PDO assignment, read as SOEM's config_map reads it, must
        give the byte counts (and entry sizes, if known) the driver expects."""
        self.coe_checked = []
        for slave, spec in zip(self.slaves, self.expected):
            if not self._offers_coe(slave):
                continue
            self.coe_checked.append(spec.name)
            try:
                layout = self._read_pdo_layout(slave)
            except (self.pysoem.SdoError, self.pysoem.MailboxError, self.pysoem.WkcError,
                    self.pysoem.PacketError) as error:
                raise BringUpError(f"slave {spec.name} ({slave.name}) offers CoE but its PDO assignment cannot be "
                                   f"read: {error}") from None
            found = {kind: (sum(bits) // 8, tuple(bits), ", ".join(f"0x{i:04X}" for i in pdos) or "none")
                     for kind, (pdos, bits) in layout.items()}
            want = {SM_OUTPUTS: (spec.output_bytes, spec.output_bits), SM_INPUTS: (spec.input_bytes, spec.input_bits)}
            if any(found[k][0] != want[k][0] or (want[k][1] and found[k][1] != want[k][1]) for k in want):
                def say(kind: int, what: str) -> str:
                    nbytes, bits, pdos = found[kind]
                    return f"{what} {pdos} ({len(bits)} entries, {nbytes} bytes)"
                raise BringUpError(
                    f"slave {spec.name} ({slave.name}) assigns over CoE {say(SM_OUTPUTS, 'outputs')} and "
                    f"{say(SM_INPUTS, 'inputs')}; the driver expects {spec.output_bytes} output bytes"
                    + (f" in {len(spec.output_bits)} entries" if spec.output_bits else "")
                    + f" and {spec.input_bytes} input bytes"
                    + (f" in {len(spec.input_bits)} entries" if spec.input_bits else ""))

    @staticmethod
    def _offers_coe(slave) -> bool:
        """As SOEM decides: a mailbox whose protocols (SII word 0x1C) include CoE."""
        protocols = int.from_bytes(slave.eeprom_read(MBX_PROTOCOLS_WORD)[:2], "little")
        return bool(protocols & MBX_COE)

    @staticmethod
    def _read_pdo_layout(slave) -> dict[int, tuple[list[int], list[int]]]:
        """{SM type: (assigned PDO indices, bit length of each mapped entry)} for outputs and inputs,
        from 0x1C00 (SM types), 0x1C1n (assignment of SM n) and the mapping objects."""
        def read(index: int, sub: int) -> int:
            return int.from_bytes(slave.sdo_read(index, sub), "little")

        layout: dict[int, tuple[list[int], list[int]]] = {SM_OUTPUTS: ([], []), SM_INPUTS: ([], [])}
        for sm in range(2, read(0x1C00, 0)):
            kind = read(0x1C00, sm + 1)
            if kind not in layout:
                continue
            for n in range(1, read(0x1C10 + sm, 0) + 1):
                pdo = read(0x1C10 + sm, n)
                layout[kind][0].append(pdo)
                layout[kind][1].extend(read(pdo, sub) & 0xFF for sub in range(1, read(pdo, 0) + 1))
        return layout

    # --- distributed clocks --------------------------------------------------------------
    def _configure_clocks(self) -> None:
        """Measure the clocks (before the mapping, so SYNC0 start times are in system time)
        and give each SYNC0 slave its pulse in the PRE-OP -> SAFE-OP hook."""
        self.distributed_clocks = bool(self.master.config_dc())
        self.sync0 = []
        if not self.distributed_clocks:
            return
        for slave, spec in zip(self.slaves, self.expected):
            if spec.sync0:
                slave.setup_func = self._start_sync0
                self.sync0.append(spec.name)

    def _start_sync0(self, slave) -> None:
        slave.dc_sync(True, self.cycle_ns)

    def _check_slaves(self) -> None:
        found = [(s.name, s.id) for s in self.slaves]
        if len(found) != len(self.expected):
            listing = ", ".join(f"{n} 0x{p:08X}" for n, p in found)
            raise BringUpError(f"found {len(found)} slaves on '{self.interface}', expected {len(self.expected)} "
                               f"({', '.join(e.name for e in self.expected)}): {listing}")
        for position, ((name, product), spec) in enumerate(zip(found, self.expected)):
            if product != spec.product:
                raise BringUpError(f"slave {position} is {name} with product code 0x{product:08X}; "
                                   f"expected {spec.name} with product code 0x{spec.product:08X}")

    # --- the cycle -----------------------------------------------------------------------
    def exchange(self) -> int:
        """One send/receive of the process data; the working counter, or -1 if no frame came back."""
        self.send()
        return self.receive()

    def send(self) -> None:
        """Send the outputs; the frame picks up the inputs on its way round the segment."""
        self.master.send_processdata()

    def receive(self) -> int:
        """The frame `send` sent, back (a cycle that computes in between sends at its end and
        receives at the start of the next); its working counter, or -1 if it did not return."""
        self.last_wkc = self.master.receive_processdata(self.receive_timeout_us)
        return self.last_wkc

    def write_outputs(self, position: int, image: np.ndarray) -> None:
        """A slave's outputs from a uint8 row, refused if its length is not the slave's."""
        slave = self.slaves[position]
        spec = self.expected[position]
        if image.nbytes != spec.output_bytes:
            raise ValueError(f"outputs of {spec.name} are {spec.output_bytes} bytes, got {image.nbytes}")
        slave.output = image.tobytes()

    def read_inputs(self, position: int, out: np.ndarray) -> None:
        data = self.slaves[position].input
        if len(data) != out.nbytes:
            raise ValueError(f"inputs of {self.expected[position].name} are {len(data)} bytes, buffer {out.nbytes}")
        out[:] = np.frombuffer(data, np.uint8)

    def states(self, out: np.ndarray) -> None:
        """Each slave's AL state as SOEM last read it (the watchdog reads them)."""
        for i, slave in enumerate(self.slaves):
            out[i] = slave.state

    def describe_states(self) -> str:
        return ", ".join(f"{spec.name} {state_name(s.state)}" + (f" (AL code 0x{s.al_status:04X} "
                         f"{self.pysoem.al_status_code_to_string(s.al_status)})" if s.al_status else "")
                         for s, spec in zip(self.slaves, self.expected))

    # --- shutdown ------------------------------------------------------------------------
    def close(self) -> None:
        """Every slave back to INIT, then the interface closed."""
        if not self.opened:
            return
        self.up = False
        with _lock:
            if _masters.get(self.interface) is self:
                del _masters[self.interface]  # the watchdog lets go of it
        with self.lock:
            try:
                if self.slaves:
                    self.master.state = AL_INIT
                    self.master.write_state()
                    self.master.state_check(AL_INIT, 500_000)
            finally:
                self.master.close()
                self.opened = False


class SoemLink:
    """The master block's segment through SOEM (the ropod's, or the emulated one): a
    `hapticop.devices.ethercat.link.SegmentLink`. `wheels` pairs each wheel's row of the
    images with its slave's position on the bus."""

    def __init__(self, master: SoemMaster, wheels: Sequence[tuple[int, int]], ready: Callable[[np.ndarray], bool],
                 clock_ns: Callable[[], int], log):
        self.master, self.wheels, self.ready, self.clock_ns, self.log = master, list(wheels), ready, clock_ns, log
        self.states = np.zeros(len(master.expected), np.uint8)  # bring-up's, not published
        self.started_ns: int | None = None
        self.in_flight = False  # a frame was sent and not yet received

    @property
    def expected_wkc(self) -> int:
        return self.master.expected_wkc

    def start(self, outputs: np.ndarray, inputs: np.ndarray) -> bool:
        """First call: open and bring up to OP (blocking, about 0.1 s). Then, exchanging every
        cycle so no drive's watchdog fires, wait until `ready(inputs)` (the wheels' encoders)."""
        m = self.master
        if self.started_ns is None:
            self.started_ns = self.clock_ns()
            m.open()
            try:
                m.bring_up(on_safeop=lambda: self._write(outputs))
            except Exception:
                m.close()
                raise
            self.log.info("EtherCAT segment on %s in OP: %s; IOmap working counter %d", m.interface,
                          ", ".join(s.name for s in m.slaves), m.expected_wkc)
            if m.coe_checked:
                self.log.info("PDO assignment read over CoE as expected: %s", ", ".join(m.coe_checked))
            if m.sync0:
                self.log.info("distributed clocks: SYNC0 every %d us on %s", m.cycle_ns // 1000, ", ".join(m.sync0))
        self.receive(inputs, self.states)
        self.send(outputs)  # in flight: the first cycle receives it
        if self.ready(inputs):
            self.log.info("all %d wheels report their encoders ready", len(self.wheels))
            return True
        if self.clock_ns() - self.started_ns > m.state_timeout_s * 1e9:
            raise RuntimeError("the smart wheels did not report their encoders ready (ENC_1_OK, ENC_2_OK, "
                               f"ENC_PIVOT_OK) within {m.state_timeout_s} s")
        return False

    def _write(self, outputs: np.ndarray) -> None:
        for wheel, position in self.wheels:
            self.master.write_outputs(position, outputs[wheel])

    def send(self, outputs: np.ndarray) -> None:
        self._write(outputs)
        self.master.send()
        self.in_flight = True

    def receive(self, inputs: np.ndarray, states: np.ndarray) -> int:
        if not self.in_flight:
            return -1
        m = self.master
        wkc = m.receive()
        self.in_flight = False
        for wheel, position in self.wheels:
            m.read_inputs(position, inputs[wheel])
        m.states(states)
        return wkc

    def close(self, outputs: np.ndarray) -> None:
        """Drives disabled (these outputs) before the slaves leave OP, then INIT and closed."""
        m = self.master
        if not m.opened:  # never opened, or closed when its bring-up failed
            return
        if self.in_flight:
            m.receive()
            self.in_flight = False
        if m.up:
            self._write(outputs)
            m.exchange()
        m.close()
        self.log.info("EtherCAT segment back in INIT, %s closed", m.interface)
