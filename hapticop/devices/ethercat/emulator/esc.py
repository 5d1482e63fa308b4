"""One emulated EtherCAT slave controller (ESC): registers, SII, AL states, SMs, FMMUs.

The ESC is what a master talks to: a 64 KiB address space of registers and process RAM.
This model keeps the parts a master uses: the station address, the DL status of its ports,
the AL control/status/status-code registers with the state machine (error flag and
acknowledge), the EEPROM interface over the SII image, sync managers and FMMUs as the
master programs them, and the process-data (sync-manager) watchdog. The slave's
application (its firmware) reads the output buffer only in OP and fills the input buffer.
A slave whose SII announces a mailbox gets one (hapticop.devices.ethercat.emulator.mailbox,
CoE in .coe), one with distributed clocks its DC registers (.clocks); the hooks here call them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from hapticop.devices.ethercat.emulator.clocks import DistributedClock
from hapticop.devices.ethercat.emulator.coe import object_dictionary
from hapticop.devices.ethercat.emulator.mailbox import Mailbox
from hapticop.devices.ethercat.emulator.sii import SM_INPUTS, SM_OUTPUTS, SlaveIdentity, build_sii

__all__ = ["Esc", "AlState", "AL_INIT", "AL_PREOP", "AL_BOOT", "AL_SAFEOP", "AL_OP", "AL_ERROR",
           "AL_CODE_INVALID_STATE_CHANGE", "AL_CODE_INVALID_OUTPUT_CONFIG", "AL_CODE_INVALID_INPUT_CONFIG",
           "AL_CODE_SM_WATCHDOG"]

AL_INIT, AL_PREOP, AL_BOOT, AL_SAFEOP, AL_OP, AL_ERROR = 0x01, 0x02, 0x03, 0x04, 0x08, 0x10
AL_CODE_INVALID_STATE_CHANGE = 0x0011
AL_CODE_SM_WATCHDOG = 0x001B
AL_CODE_INVALID_OUTPUT_CONFIG = 0x001D
AL_CODE_INVALID_INPUT_CONFIG = 0x001E
AlState = int

MEMORY = 0x2000  # registers 0x0000-0x0FFF, process RAM 0x1000-0x1FFF; above reads as zero
REG_STATION, REG_ALIAS = 0x0010, 0x0012
REG_DL_STATUS = 0x0110
REG_AL_CONTROL, REG_AL_STATUS, REG_AL_CODE = 0x0120, 0x0130, 0x0134
REG_EEP_CONTROL, REG_EEP_ADDRESS, REG_EEP_DATA = 0x0502, 0x0504, 0x0508
REG_WD_DIVIDER, REG_WD_PDI, REG_WD_PD, REG_WD_STATUS = 0x0400, 0x0410, 0x0420, 0x0440
REG_FMMU, REG_SM = 0x0600, 0x0800
EEP_READ, EEP_WRITE, EEP_RELOAD, EEP_READ64 = 0x0100, 0x0200, 0x0400, 0x0040
# Registers the master cannot write (identity, DL status, AL status and code, watchdog status,
# SM status, SM PDI control).
_READ_ONLY = [(0x0000, 0x0010), (0x0110, 0x0112), (0x0130, 0x0136), (0x0440, 0x0442)] + \
             [(REG_SM + 8 * n + 5, REG_SM + 8 * n + 6) for n in range(8)] + \
             [(REG_SM + 8 * n + 7, REG_SM + 8 * n + 8) for n in range(8)]
_UP = {AL_INIT: {AL_INIT, AL_PREOP, AL_BOOT}, AL_PREOP: {AL_INIT, AL_PREOP, AL_SAFEOP},
       AL_BOOT: {AL_INIT, AL_BOOT}, AL_SAFEOP: {AL_INIT, AL_PREOP, AL_SAFEOP, AL_OP},
       AL_OP: {AL_INIT, AL_PREOP, AL_SAFEOP, AL_OP}}  # the legal requests from each state


@dataclass
class Fmmu:
    logical: int
    length: int
    physical: int
    read: bool  # the master reads physical memory through it
    write: bool


class Esc:
    """One slave. `ports` is the set of its open ports (0-3), for the DL status register."""

    def __init__(self, identity: SlaveIdentity, ports: tuple[int, ...] = (0, 1), esc_type: int = 0x11):
        self.identity = identity
        self.ports = ports
        self.esc_type = esc_type
        self.eeprom = build_sii(identity)
        self.mem = bytearray(MEMORY)
        self.present = True  # False: powered off (the segment also cuts off whatever is wired behind it)
        self.fmmus: list[Fmmu] = []
        self.outputs_sm: tuple[int, int] | None = None  # (start, length) of the programmed output buffer
        self.last_output_ns = 0
        self.watchdog_expired = False
        self.error_held_until_ns = 0  # a persisting fault: acknowledgements fail until then
        self.power_on()

    # --- identity and power ------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.identity.name

    def power_on(self) -> None:
        """Every register to its reset value (a power cycle): INIT, no address, no mapping."""
        mem = self.mem
        mem[:] = bytes(MEMORY)
        mem[0], mem[1], mem[2] = self.esc_type, 0x02, 0x00
        mem[4], mem[5], mem[6] = 8, 8, MEMORY // 1024  # FMMUs, SMs, RAM (KiB)
        mem[7] = sum(0b11 << (2 * p) for p in self.ports)  # port descriptor: MII on each open port
        struct.pack_into("<H", mem, REG_ALIAS, struct.unpack_from("<H", self.eeprom, 4 * 2)[0])
        struct.pack_into("<H", mem, REG_DL_STATUS, self._dl_status())
        struct.pack_into("<H", mem, REG_AL_STATUS, AL_INIT)
        struct.pack_into("<H", mem, REG_EEP_CONTROL, EEP_READ64)
        struct.pack_into("<H", mem, REG_WD_DIVIDER, 0x09C2)  # 100 us units
        struct.pack_into("<H", mem, REG_WD_PDI, 1000)
        struct.pack_into("<H", mem, REG_WD_PD, 1000)  # 100 ms
        self.fmmus = []
        self.outputs_sm = None
        self.watchdog_expired = False
        identity = self.identity
        self.mailbox = (Mailbox(mem, identity.mailbox, object_dictionary(identity), lambda: self.state)
                        if identity.mailbox else None)
        self.clock = DistributedClock(mem, identity.requires_sync0) if identity.distributed_clocks else None

    def _dl_status(self) -> int:
        status = 0x0003  # PDI operational (EEPROM loaded), PDI watchdog not expired
        for port in range(4):
            if port in self.ports:
                status |= (0x10 << port) | (0x200 << (2 * port))  # link, loop open with communication
            else:
                status |= 0x100 << (2 * port)  # loop closed
        return status

    # --- AL state ----------------------------------------------------------------------
    @property
    def station(self) -> int:
        return struct.unpack_from("<H", self.mem, REG_STATION)[0]

    @property
    def al_status(self) -> int:
        return self.mem[REG_AL_STATUS]

    @property
    def state(self) -> int:
        return self.mem[REG_AL_STATUS] & 0x0F

    @property
    def al_code(self) -> int:
        return struct.unpack_from("<H", self.mem, REG_AL_CODE)[0]

    def _set_state(self, state: int, error: bool = False, code: int | None = None) -> None:
        self.mem[REG_AL_STATUS] = state | (AL_ERROR if error else 0)
        if code is not None:
            struct.pack_into("<H", self.mem, REG_AL_CODE, code)
        if state < AL_SAFEOP:
            self.watchdog_expired = False

    def raise_error(self, code: int, state: int | None = None, until_ns: int = 0) -> None:
        """The application reports an error: ERR flag, the code, and a fall-back state
        (SAFE-OP from OP, as a drive does; otherwise where it is). Until `until_ns` the cause
        persists, so acknowledging does not clear it."""
        fallback = state if state is not None else min(self.state, AL_SAFEOP)
        self._set_state(fallback, error=True, code=code)
        self.error_held_until_ns = until_ns

    def _al_control(self, now_ns: int) -> None:
        value = struct.unpack_from("<H", self.mem, REG_AL_CONTROL)[0]
        requested, ack = value & 0x0F, bool(value & AL_ERROR)
        if requested == AL_INIT:  # INIT is always honoured and clears the error, acknowledged or not
            struct.pack_into("<H", self.mem, REG_AL_CODE, 0)
            self.error_held_until_ns = 0
            self._set_state(AL_INIT)
            return
        error = bool(self.al_status & AL_ERROR)
        if error and (not ack or now_ns < self.error_held_until_ns):
            return  # an error must be acknowledged (and its cause gone) before the state machine moves again
        if ack:
            struct.pack_into("<H", self.mem, REG_AL_CODE, 0)
        current = self.state
        if requested not in _UP.get(current, ()):
            self._set_state(current, error=True, code=AL_CODE_INVALID_STATE_CHANGE)
            return
        if requested != AL_INIT and current == AL_INIT and self.mailbox is not None:
            code = self.mailbox.check_config()
            if code:
                self._set_state(current, error=True, code=code)
                return
        if requested in (AL_SAFEOP, AL_OP) and current < AL_SAFEOP:
            code = self._check_process_data() or (self.clock.check_sync() if self.clock else 0)
            if code:
                self._set_state(current, error=True, code=code)
                return
            self.last_output_ns = 0  # the watchdog counts from the first output write
        self._set_state(requested)

    def _check_process_data(self) -> int:
        """PRE-OP -> SAFE-OP: the master's SM programming must match the SII's (else 0x001D/0x001E)."""
        self.outputs_sm = None
        for n, spec in enumerate(self.identity.sync_managers):
            start, length, control, _, enable = struct.unpack_from("<HHBBB", self.mem, REG_SM + 8 * n)
            expected = spec.length if self.mailbox is None else self.mailbox.assigned_bytes(n)
            ok = start == spec.start and length == expected and enable & 1
            if spec.kind == SM_OUTPUTS:
                if not ok:
                    return AL_CODE_INVALID_OUTPUT_CONFIG
                self.outputs_sm = (start, length)
            elif spec.kind == SM_INPUTS and not ok:
                return AL_CODE_INVALID_INPUT_CONFIG
        return 0

    def _read_fmmus(self) -> list[Fmmu]:
        fmmus = []
        for n in range(8):
            logical, length, _, _, physical, _, kind, active = struct.unpack_from(
                "<IHBBHBBB", self.mem, REG_FMMU + 16 * n)
            if active & 1 and length:
                fmmus.append(Fmmu(logical, length, physical, bool(kind & 1), bool(kind & 2)))
        return fmmus

    # --- the process-data watchdog -----------------------------------------------------
    def watchdog_ns(self) -> int:
        """The SM watchdog time the master programmed (0: off); units from the divider."""
        if self.outputs_sm is None:
            return 0
        n = next(i for i, s in enumerate(self.identity.sync_managers) if s.kind == SM_OUTPUTS)
        if not self.mem[REG_SM + 8 * n + 4] & 0x40:  # watchdog enable bit of the SM control
            return 0
        divider, time = (struct.unpack_from("<H", self.mem, REG_WD_DIVIDER)[0],
                         struct.unpack_from("<H", self.mem, REG_WD_PD)[0])
        return time * (divider + 2) * 40  # 25 MHz clock: 40 ns per tick

    def tick(self, now_ns: int) -> None:
        """Expire the watchdog when the outputs have not been written in time (in OP)."""
        if self.state != AL_OP or self.last_output_ns == 0 or self.watchdog_expired:
            return
        limit = self.watchdog_ns()
        if limit and now_ns - self.last_output_ns > limit:
            self.trip_watchdog()

    def trip_watchdog(self) -> None:
        self.watchdog_expired = True
        struct.pack_into("<H", self.mem, REG_WD_STATUS, 0)
        self.raise_error(AL_CODE_SM_WATCHDOG)

    @property
    def outputs_live(self) -> bool:
        """The application applies the outputs: OP, and the watchdog has not fired."""
        return self.present and self.state == AL_OP and not self.watchdog_expired

    def output_buffer(self) -> memoryview | None:
        if self.outputs_sm is None:
            return None
        start, length = self.outputs_sm
        return memoryview(self.mem)[start:start + length]

    def input_buffer(self) -> memoryview | None:
        for spec in self.identity.sync_managers:
            if spec.kind == SM_INPUTS:
                return memoryview(self.mem)[spec.start:spec.start + spec.length]
        return None

    def write_inputs(self, data: bytes | memoryview) -> None:
        """The application fills its input buffer (the SII's input SM area)."""
        for spec in self.identity.sync_managers:
            if spec.kind == SM_INPUTS:
                self.mem[spec.start:spec.start + len(data)] = data
                return

    # --- register access by the master -------------------------------------------------
    def read(self, ado: int, out: memoryview, combine: bool = False) -> bool:
        """Copy registers [ado, ado+len) into `out` (OR them in for broadcast reads); False if
        the ESC refuses the read (an empty send mailbox): no data, no working counter."""
        n = len(out)
        end = min(ado + n, MEMORY)
        if ado >= MEMORY:
            if not combine:
                out[:] = bytes(n)
            return True
        if self.clock is not None:
            self.clock.before_read(ado, end)
        if self.mailbox is not None and not self.mailbox.may_read(ado, end):
            return False
        chunk = self.mem[ado:end] + bytes(n - (end - ado))
        if combine:
            out[:] = bytes(a | b for a, b in zip(out, chunk))
        else:
            out[:] = chunk
        if self.mailbox is not None:
            self.mailbox.read_done(ado, end)
        return True

    def write(self, ado: int, data: memoryview, now_ns: int) -> bool:
        """Write registers with their side effects (AL control, EEPROM command, output buffer);
        False if the ESC refuses the write (a full receive mailbox): nothing written, no count."""
        n = len(data)
        end = min(ado + n, MEMORY)
        if ado >= MEMORY:
            return True
        if self.mailbox is not None and not self.mailbox.may_write(ado, end):
            return False
        saved = [(a, b, bytes(self.mem[a:b])) for a, b in _READ_ONLY if a < end and b > ado]
        self.mem[ado:end] = data[:end - ado]
        for a, b, old in saved:
            self.mem[a:b] = old
        if ado <= REG_AL_CONTROL < end:
            self._al_control(now_ns)
        if ado <= REG_EEP_CONTROL < end or ado <= REG_EEP_CONTROL + 1 < end:
            self._eeprom_command()
        if ado < REG_FMMU + 16 * 8 and end > REG_FMMU:
            self.fmmus = self._read_fmmus()  # SOEM may program FMMUs after SAFE-OP (reconfig does)
        self._note_output_write(ado, end, now_ns)
        if self.mailbox is not None:
            self.mailbox.written(ado, end)
        if self.clock is not None:
            self.clock.after_write(ado, end, data)
        return True

    def _note_output_write(self, start: int, end: int, now_ns: int) -> None:
        sm = self.outputs_sm
        if sm is not None and start < sm[0] + sm[1] <= end:  # the buffer's last byte completes it
            self.last_output_ns = now_ns  # a complete write re-arms the watchdog, after a trip too
            self.watchdog_expired = False
            struct.pack_into("<H", self.mem, REG_WD_STATUS, 1)

    def _eeprom_command(self) -> None:
        control = struct.unpack_from("<H", self.mem, REG_EEP_CONTROL)[0]
        address = struct.unpack_from("<I", self.mem, REG_EEP_ADDRESS)[0] * 2
        if control & EEP_READ:
            chunk = self.eeprom[address:address + 8]
            self.mem[REG_EEP_DATA:REG_EEP_DATA + 8] = chunk + b"\xff" * (8 - len(chunk))
        elif control & EEP_WRITE and address + 2 <= len(self.eeprom):
            self.eeprom[address:address + 2] = self.mem[REG_EEP_DATA:REG_EEP_DATA + 2]
        # The command completes at once: not busy, no NACK, no error; 8-byte reads supported.
        struct.pack_into("<H", self.mem, REG_EEP_CONTROL, (control & 0x0001) | EEP_READ64)

    # --- logical addressing ------------------------------------------------------------
    def logical(self, address: int, frame: memoryview, reads: bool, writes: bool, now_ns: int) -> int:
        """LRD/LWR/LRW through the FMMUs; returns this slave's working-counter increment."""
        if self.state < AL_SAFEOP:
            return 0
        end = address + len(frame)
        did_read = did_write = False
        for f in self.fmmus:
            lo, hi = max(address, f.logical), min(end, f.logical + f.length)
            if lo >= hi:
                continue
            phys = f.physical + lo - f.logical
            span = frame[lo - address:hi - address]
            if f.write and writes:
                self.mem[phys:phys + len(span)] = span
                self._note_output_write(phys, phys + len(span), now_ns)
                did_write = True
            elif f.read and reads:
                span[:] = self.mem[phys:phys + len(span)]
                did_read = True
        return (1 if did_read else 0) + ((2 if reads else 1) if did_write else 0)
