"""The standard mailbox of an emulated ESC: SM0 takes the master's requests, SM1 holds the answers.

A mailbox sync manager is a single buffer with a handshake, not plain memory. The master
writes the whole receive mailbox (SM0); writing its last byte makes it full (bit 3 of the
SM status register), and while it is full the ESC refuses further writes to it (no write,
no working counter). The slave's application takes the request, which empties SM0, and
puts its answer in the send mailbox (SM1), which is then full; the master reads it once:
reading its last byte empties it, and a read of the empty buffer is refused the same way.
An answer waits for the master to fetch the last one, so a request stays in SM0 until
SM1 is free. The application serves its mailbox from PRE-OP on; INIT clears both.

A reply frame can be lost after the ESC emptied SM1: the answer is gone from the buffer but
never reached the master. The master then toggles the repeat request (bit 1 of SM1's
activate register); the application puts its last answer back in SM1 and mirrors the bit
into SM1's PDI control register (the repeat acknowledge), which is how SOEM recovers it.
CoE requests go to the slave's SDO server; other protocols get a mailbox error.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from hapticop.devices.ethercat.emulator.coe import ObjectDictionary, SdoServer
from hapticop.devices.ethercat.emulator.sii import MailboxSpec

__all__ = ["Mailbox", "MBX_ERROR", "MBX_COE", "MBXERR_UNSUPPORTED_PROTOCOL", "MBXERR_SERVICE_NOT_SUPPORTED",
           "MBXERR_INVALID_SIZE", "AL_CODE_INVALID_MAILBOX_CONFIG", "SM_FULL"]

MBX_ERROR, MBX_COE = 0x00, 0x03  # mailbox header type
MBXERR_UNSUPPORTED_PROTOCOL, MBXERR_SERVICE_NOT_SUPPORTED, MBXERR_INVALID_SIZE = 0x0002, 0x0004, 0x0008
AL_CODE_INVALID_MAILBOX_CONFIG = 0x0016
SM_FULL = 0x08  # SM status register: mailbox full
REG_SM, REG_AL_CONTROL = 0x0800, 0x0120
_ACTIVATE, _PDI_CONTROL, _REPEAT = 6, 7, 0x02  # SM register offsets; the repeat request / acknowledge bit
_HEADER = 6  # length, address, channel/priority, type/counter
AL_INIT, AL_PREOP, AL_BOOT = 0x01, 0x02, 0x03


class Mailbox:
    """SM0/SM1 of one ESC's memory `mem`; `state()` is the slave's AL state."""

    def __init__(self, mem: bytearray, spec: MailboxSpec, objects: ObjectDictionary, state: Callable[[], int]):
        self.mem, self.spec, self.state = mem, spec, state
        self.sdo = SdoServer(objects, state, spec.send_size - _HEADER - 10)
        self.counter = 0
        self.taken = 0  # answers the master has read out of SM1 (a fault can drop the frame carrying one)
        self.reset()

    def assigned_bytes(self, sm: int) -> int:
        """The length of process-data SM `sm` as the CoE PDO assignment says (what SAFE-OP checks)."""
        return self.sdo.objects.assigned_bits(sm) // 8

    def reset(self) -> None:
        """Both buffers empty (power-on, INIT)."""
        self.request_full = self.answer_full = False
        self.last_answer = b""
        self._publish()

    # --- the sync managers as the master programmed them -------------------------------
    def _sm(self, n: int) -> tuple[int, int, bool]:
        start, length, _, _, activate = struct.unpack_from("<HHBBB", self.mem, REG_SM + 8 * n)
        return start, length, bool(activate & 1) and length > 0

    def check_config(self) -> int:
        """INIT -> PRE-OP: SM0/SM1 must be the SII's mailbox, in mailbox mode, enabled (else 0x0016)."""
        spec = self.spec
        expected = ((spec.receive_at, spec.receive_size, 0x04), (spec.send_at, spec.send_size, 0x00))
        for n, (start, length, direction) in enumerate(expected):
            at, size, enabled = self._sm(n)
            control = self.mem[REG_SM + 8 * n + 4]
            if (at, size) != (start, length) or not enabled or control & 0x0F != 0x02 | direction:
                return AL_CODE_INVALID_MAILBOX_CONFIG
        return 0

    def _publish(self) -> None:
        for n, full in ((0, self.request_full), (1, self.answer_full)):
            at = REG_SM + 8 * n + 5
            self.mem[at] = (self.mem[at] & ~SM_FULL) | (SM_FULL if full else 0)

    # --- the master's accesses (hooks of the ESC's read and write) ----------------------
    def _touches(self, n: int, start: int, end: int) -> tuple[bool, bool]:
        """Whether [start, end) touches SM n's buffer, and whether it reaches its last byte."""
        at, size, enabled = self._sm(n)
        if not enabled:
            return False, False
        return start < at + size and end > at, start < at + size <= end

    def may_write(self, start: int, end: int) -> bool:
        """A write into a full receive mailbox, or into the send mailbox, is refused."""
        if self._touches(1, start, end)[0]:
            return False
        return not (self.request_full and self._touches(0, start, end)[0])

    def may_read(self, start: int, end: int) -> bool:
        """A read of the send mailbox while it holds no answer is refused."""
        return self.answer_full or not self._touches(1, start, end)[0]

    def written(self, start: int, end: int) -> None:
        touched, completed = self._touches(0, start, end)
        if completed:
            self.request_full = True
        if start <= REG_SM + 8 + _ACTIVATE < end:
            self._repeat_if_asked()
        if touched or start <= REG_AL_CONTROL < end:  # a request, or a state the application acts on
            self.serve()

    def read_done(self, start: int, end: int) -> None:
        if self.answer_full and self._touches(1, start, end)[1]:
            self.answer_full = False
            self.taken += 1
            self.serve()

    def _repeat_if_asked(self) -> None:
        """The master toggled SM1's repeat request: the last answer goes back into SM1 and the
        acknowledge bit follows the request bit."""
        asked = self.mem[REG_SM + 8 + _ACTIVATE] & _REPEAT
        at = REG_SM + 8 + _PDI_CONTROL
        if asked == self.mem[at] & _REPEAT:
            return
        if self.last_answer and not self.answer_full:
            start, size, _ = self._sm(1)
            self.mem[start:start + size] = self.last_answer
            self.answer_full = True
        self.mem[at] = (self.mem[at] & ~_REPEAT) | asked
        self._publish()

    # --- the slave's application ------------------------------------------------------
    def serve(self) -> None:
        """Take a waiting request and answer it, if the answer has somewhere to go."""
        state = self.state()
        if state == AL_INIT:
            self.reset()
            return
        if self.request_full and not self.answer_full and state != AL_BOOT:
            at, size, _ = self._sm(0)
            request = bytes(self.mem[at:at + size])
            self.request_full = False
            self._answer(request)
        self._publish()

    def _answer(self, request: bytes) -> None:
        length, _, _, kind = struct.unpack_from("<HHBB", request)
        payload = request[_HEADER:_HEADER + length]
        if length > len(request) - _HEADER:
            kind, answer = MBX_ERROR, struct.pack("<HH", 1, MBXERR_INVALID_SIZE)
        elif kind & 0x0F != MBX_COE:
            kind, answer = MBX_ERROR, struct.pack("<HH", 1, MBXERR_UNSUPPORTED_PROTOCOL)
        elif len(payload) < 2 or struct.unpack_from("<H", payload)[0] >> 12 != 2:  # service 2: SDO request
            kind, answer = MBX_ERROR, struct.pack("<HH", 1, MBXERR_SERVICE_NOT_SUPPORTED)
        else:
            kind, answer = MBX_COE, self.sdo.answer(payload)
        self.counter = self.counter % 7 + 1  # 1..7: a new message, not a repeat
        at, size, _ = self._sm(1)
        message = struct.pack("<HHBB", len(answer), 0, 0, kind | self.counter << 4) + answer
        self.last_answer = message[:size].ljust(size, b"\0")
        self.mem[at:at + size] = self.last_answer
        self.answer_full = True
