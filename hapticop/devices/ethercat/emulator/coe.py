"""CoE for an emulated slave: its object dictionary and the SDO server that answers over the mailbox.

A slave with CoE tells the master what it exchanges through objects rather than the SII: the
sync-manager communication types (0x1C00), the PDO assignment of each process-data sync
manager (0x1C12 outputs, 0x1C13 inputs) and the PDO mappings they name (0x16xx, 0x1Axx),
each mapped entry a 32-bit word `index << 16 | subindex << 8 | bit length`. A master that
reads these (SOEM's config_map does) sizes the process data from them. Access follows
CiA 301 as ETG.1000.6 carries it over EtherCAT: expedited transfers for up to four bytes,
normal ones (size first, data in the same mailbox) beyond, and an abort code when a request
cannot be served. The PDO assignment is writable in PRE-OP only, as on real slaves.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

from hapticop.devices.ethercat.emulator.sii import SM_INPUTS, SM_OUTPUTS, Pdo, SlaveIdentity

__all__ = ["ObjectEntry", "ObjectDictionary", "SdoServer", "SdoAbort", "object_dictionary",
           "ABORT_TOGGLE", "ABORT_COMMAND", "ABORT_UNSUPPORTED_ACCESS", "ABORT_READ_ONLY", "ABORT_NO_OBJECT",
           "ABORT_LENGTH", "ABORT_TOO_LONG", "ABORT_TOO_SHORT", "ABORT_NO_SUBINDEX", "ABORT_VALUE_RANGE",
           "ABORT_DEVICE_STATE", "UNSIGNED8", "UNSIGNED16", "UNSIGNED32", "VISIBLE_STRING"]

UNSIGNED8, UNSIGNED16, UNSIGNED32, VISIBLE_STRING = 0x0005, 0x0006, 0x0007, 0x0009
ABORT_TOGGLE = 0x05030000
ABORT_COMMAND = 0x05040001  # client/server command specifier not valid or unknown
ABORT_UNSUPPORTED_ACCESS = 0x06010000
ABORT_READ_ONLY = 0x06010002
ABORT_NO_OBJECT = 0x06020000
ABORT_LENGTH = 0x06070010  # data type does not match, length of service parameter does not match
ABORT_TOO_LONG, ABORT_TOO_SHORT = 0x06070012, 0x06070013
ABORT_NO_SUBINDEX = 0x06090011
ABORT_VALUE_RANGE = 0x06090030
ABORT_DEVICE_STATE = 0x08000022  # cannot be transferred or stored because of the present device state

_FORMATS = {UNSIGNED8: "<B", UNSIGNED16: "<H", UNSIGNED32: "<I"}
AL_PREOP = 0x02


class SdoAbort(Exception):
    def __init__(self, code: int):
        super().__init__(f"SDO abort 0x{code:08X}")
        self.code = code


@dataclass
class ObjectEntry:
    """One subindex: its type and value; `writable_in` the AL states it accepts a download in
    (empty: read only); `check(value)` may refuse a value with an abort code."""
    data_type: int
    value: int | bytes
    writable_in: tuple[int, ...] = ()
    check: Callable[[int | bytes], int] | None = None

    def encode(self) -> bytes:
        if self.data_type == VISIBLE_STRING:
            return bytes(self.value)
        return struct.pack(_FORMATS[self.data_type], self.value)

    @property
    def size(self) -> int:
        return len(self.encode())


class ObjectDictionary:
    """index -> {subindex -> entry}; a record's subindex 0 is its entry count."""

    def __init__(self):
        self.objects: dict[int, dict[int, ObjectEntry]] = {}

    def add(self, index: int, *entries: ObjectEntry) -> None:
        self.objects[index] = dict(enumerate(entries))

    def add_record(self, index: int, data_type: int, values, writable_in: tuple[int, ...] = (),
                   check=None, count_check=None) -> None:
        """A record or array: subindex 0 holds the count, 1.. the values (of one type)."""
        subs = [ObjectEntry(UNSIGNED8, len(values), writable_in, count_check)]
        subs += [ObjectEntry(data_type, v, writable_in, check) for v in values]
        self.add(index, *subs)

    def entry(self, index: int, subindex: int) -> ObjectEntry:
        obj = self.objects.get(index)
        if obj is None:
            raise SdoAbort(ABORT_NO_OBJECT)
        entry = obj.get(subindex)
        if entry is None:
            raise SdoAbort(ABORT_NO_SUBINDEX)
        return entry

    def values(self, index: int) -> list[int]:
        """The values of subindices 1..count of a record (the count as subindex 0 says)."""
        obj = self.objects[index]
        return [obj[sub].value for sub in range(1, obj[0].value + 1)]

    def assigned_bits(self, sm: int) -> int:
        """The process data of sync manager `sm` as its PDO assignment (0x1C10 + sm) says."""
        index = 0x1C10 + sm
        if index not in self.objects:
            return 0
        return sum((word & 0xFF) for pdo in self.values(index) for word in self.values(pdo))


class SdoServer:
    """Answers one CoE SDO request (the CoE payload after the mailbox header) with the answer's
    payload; `state()` is the slave's AL state, which writable objects are checked against."""

    def __init__(self, objects: ObjectDictionary, state: Callable[[], int], max_data: int):
        self.objects, self.state, self.max_data = objects, state, max_data

    def answer(self, request: bytes) -> bytes:
        if len(request) < 10:
            return self._abort(0, 0, ABORT_COMMAND)
        _, command, index, subindex = struct.unpack_from("<HBHB", request)
        data = request[6:10]
        try:
            if command & 0x10:  # complete access: not offered (CoE details leave it out)
                raise SdoAbort(ABORT_UNSUPPORTED_ACCESS)
            specifier = command >> 5
            if specifier == 2:
                return self._upload(index, subindex)
            if specifier == 1:
                return self._download(index, subindex, command, data, request[10:])
            raise SdoAbort(ABORT_COMMAND)  # segmented transfers: every object fits one mailbox
        except SdoAbort as abort:
            return self._abort(index, subindex, abort.code)

    @staticmethod
    def _response(command: int, index: int, subindex: int, data: bytes, service: int = 3) -> bytes:
        return struct.pack("<HBHB", service << 12, command, index, subindex) + data  # service 3: SDO response

    def _abort(self, index: int, subindex: int, code: int) -> bytes:
        """An abort travels as an SDO request (CoE service 2), not as a response."""
        return self._response(0x80, index, subindex, struct.pack("<I", code), service=2)

    def _upload(self, index: int, subindex: int) -> bytes:
        value = self.objects.entry(index, subindex).encode()
        if len(value) <= 4:  # expedited: size indicated, the unused bytes counted in bits 2-3
            return self._response(0x43 | (4 - len(value)) << 2, index, subindex, value.ljust(4, b"\0"))
        if len(value) > self.max_data:
            raise SdoAbort(ABORT_UNSUPPORTED_ACCESS)
        return self._response(0x41, index, subindex, struct.pack("<I", len(value)) + value)

    def _download(self, index: int, subindex: int, command: int, data: bytes, rest: bytes) -> bytes:
        entry = self.objects.entry(index, subindex)
        if command & 0x02:  # expedited
            value = data[:4 - (command >> 2 & 0x03)] if command & 0x01 else data[:entry.size]
        else:  # normal: the size first, the data after it
            if not command & 0x01:
                raise SdoAbort(ABORT_COMMAND)
            (size,) = struct.unpack("<I", data)
            if size > len(rest):
                raise SdoAbort(ABORT_COMMAND)  # would need segments
            value = rest[:size]
        if not entry.writable_in:
            raise SdoAbort(ABORT_READ_ONLY)
        if entry.data_type != VISIBLE_STRING and len(value) != entry.size:
            raise SdoAbort(ABORT_TOO_LONG if len(value) > entry.size else ABORT_TOO_SHORT)
        if self.state() not in entry.writable_in:
            raise SdoAbort(ABORT_DEVICE_STATE)
        new = bytes(value) if entry.data_type == VISIBLE_STRING else struct.unpack(_FORMATS[entry.data_type], value)[0]
        code = entry.check(new) if entry.check else 0
        if code:
            raise SdoAbort(code)
        entry.value = new
        return self._response(0x60, index, subindex, bytes(4))


def _mapping(pdo: Pdo) -> list[int]:
    return [e.index << 16 | e.subindex << 8 | e.bits for e in pdo.entries]


def object_dictionary(identity: SlaveIdentity, device_type: int = 0) -> ObjectDictionary:
    """The objects a master reads from a slave with CoE: device type (0: no standard device
    profile), name and software version, identity, the SM types, the PDO mappings of its SII PDOs and their
    assignment to the process-data SMs."""
    od = ObjectDictionary()
    od.add(0x1000, ObjectEntry(UNSIGNED32, device_type))
    od.add(0x1008, ObjectEntry(VISIBLE_STRING, identity.name.encode("ascii")))
    od.add(0x100A, ObjectEntry(VISIBLE_STRING, b"hapticop emulator"))  # software version: this one
    od.add_record(0x1018, UNSIGNED32, [identity.vendor, identity.product, identity.revision, identity.serial])
    for pdo in identity.rx_pdos + identity.tx_pdos:
        od.add_record(pdo.index, UNSIGNED32, _mapping(pdo))
    kinds = [spec.kind for spec in identity.sync_managers]
    od.add_record(0x1C00, UNSIGNED8, kinds)
    for sm, kind in enumerate(kinds):
        if kind not in (SM_OUTPUTS, SM_INPUTS):
            continue
        pdos = [p for p in (identity.rx_pdos if kind == SM_OUTPUTS else identity.tx_pdos) if p.sync_manager == sm]
        known = {p.index for p in pdos}
        od.add_record(0x1C10 + sm, UNSIGNED16, [p.index for p in pdos], writable_in=(AL_PREOP,),
                      check=lambda v, known=known: 0 if v in known else ABORT_VALUE_RANGE,
                      count_check=lambda n, most=len(pdos): 0 if n <= most else ABORT_VALUE_RANGE)
    return od
