"""The SII EEPROM image of an EtherCAT slave: identity words and categories.

A master learns who a slave is from this image: identity at words 0x08-0x0F, the standard
mailbox (offsets, sizes, protocols) at words 0x18-0x1C, and from word 0x40 a chain of
categories (type, length in words, data) ending with 0xFFFF. A slave without a mailbox is
mapped from its PDO categories alone; one with CoE announces it here (protocol word, CoE
details in the general category) and the master reads its PDO assignment over SDO. The
layout follows ETG.1000.6 / ETG.2010; only what a master reads is filled in.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

__all__ = ["PdoEntry", "Pdo", "SyncManagerSpec", "MailboxSpec", "SlaveIdentity", "build_sii",
           "CAT_STRINGS", "CAT_GENERAL", "CAT_FMMU", "CAT_SM", "CAT_TXPDO", "CAT_RXPDO",
           "SM_MAILBOX_OUT", "SM_MAILBOX_IN", "SM_OUTPUTS", "SM_INPUTS", "FMMU_OUTPUTS", "FMMU_INPUTS",
           "MBX_COE", "COE_SDO", "COE_PDO_ASSIGN"]

CAT_STRINGS, CAT_GENERAL, CAT_FMMU, CAT_SM, CAT_TXPDO, CAT_RXPDO = 10, 30, 40, 41, 50, 51
# SM category type byte: mailbox master->slave, mailbox slave->master, process data master->slave, slave->master
SM_MAILBOX_OUT, SM_MAILBOX_IN, SM_OUTPUTS, SM_INPUTS = 1, 2, 3, 4
FMMU_OUTPUTS, FMMU_INPUTS = 1, 2  # FMMU category usage byte
MBX_COE = 0x0004  # mailbox protocol word (0x1C): CoE
COE_SDO, COE_PDO_ASSIGN = 0x01, 0x04  # CoE details (general category byte 5): SDO, PDO assignment readable


@dataclass(frozen=True)
class PdoEntry:
    index: int
    subindex: int
    bits: int
    data_type: int = 0


@dataclass(frozen=True)
class Pdo:
    index: int  # 0x16xx (RxPDO, outputs) or 0x1Axx (TxPDO, inputs)
    sync_manager: int
    entries: tuple[PdoEntry, ...]

    @property
    def bits(self) -> int:
        return sum(e.bits for e in self.entries)


@dataclass(frozen=True)
class SyncManagerSpec:
    start: int  # physical address in the ESC memory
    length: int
    control: int  # register 0x0804: buffer type, direction, watchdog enable
    kind: int  # SM_OUTPUTS or SM_INPUTS
    enable: int = 1


@dataclass(frozen=True)
class MailboxSpec:
    """The standard mailbox: where the master writes requests (SM0) and reads answers (SM1)."""
    receive_at: int  # the slave receives: SM0, written by the master
    receive_size: int
    send_at: int  # the slave sends: SM1, read by the master
    send_size: int
    protocols: int = MBX_COE
    coe_details: int = COE_SDO | COE_PDO_ASSIGN


@dataclass(frozen=True)
class SlaveIdentity:
    name: str
    vendor: int
    product: int
    revision: int
    serial: int = 0
    sync_managers: tuple[SyncManagerSpec, ...] = ()
    fmmus: tuple[int, ...] = ()  # usage per FMMU
    rx_pdos: tuple[Pdo, ...] = ()
    tx_pdos: tuple[Pdo, ...] = ()
    ebus_current_ma: int = 0
    strings: tuple[str, ...] = field(default=())  # extra strings after the name
    mailbox: MailboxSpec | None = None
    distributed_clocks: bool = False  # the ESC has DC (register 0x0008 bit 2)
    requires_sync0: bool = False  # the application runs on SYNC0 only: SAFE-OP needs it configured


def _crc8(data: bytes) -> int:
    """The SII configuration-area checksum (polynomial x^8 + x^2 + x + 1, initial 0xFF)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def _category(kind: int, data: bytes) -> bytes:
    if len(data) % 2:
        data += b"\0"
    return struct.pack("<HH", kind, len(data) // 2) + data


def _pdo_category(kind: int, pdos: tuple[Pdo, ...]) -> bytes:
    out = bytearray()
    for pdo in pdos:
        out += struct.pack("<HBBBBH", pdo.index, len(pdo.entries), pdo.sync_manager, 0, 0, 0)
        for e in pdo.entries:
            out += struct.pack("<HBBBBH", e.index, e.subindex, 0, e.data_type, e.bits, 0)
    return _category(kind, bytes(out))


def build_sii(identity: SlaveIdentity, size_bytes: int = 2048) -> bytearray:
    """The EEPROM contents, `size_bytes` long, unused words 0xFFFF."""
    words = bytearray(b"\xff" * size_bytes)
    config = bytearray(16)  # words 0-7: PDI control, configuration, pulse length, alias, checksum
    config[14:16] = struct.pack("<H", _crc8(bytes(config[:14])))
    words[0:16] = config
    struct.pack_into("<IIII", words, 0x08 * 2, identity.vendor, identity.product, identity.revision, identity.serial)
    mbx = identity.mailbox
    struct.pack_into("<4H", words, 0x14 * 2, 0, 0, 0, 0)  # no bootstrap mailbox
    struct.pack_into("<5H", words, 0x18 * 2, *((mbx.receive_at, mbx.receive_size, mbx.send_at, mbx.send_size,
                                                 mbx.protocols) if mbx else (0, 0, 0, 0, 0)))
    struct.pack_into("<HH", words, 0x3E * 2, size_bytes // 128 - 1, 1)  # size in KiBit - 1, version

    strings = (identity.name, *identity.strings)
    encoded = bytes([len(strings)]) + b"".join(bytes([len(s)]) + s.encode("ascii") for s in strings)
    general = bytearray(32)
    general[0] = general[1] = general[2] = 0
    general[3] = 1  # name: string 1
    general[5] = mbx.coe_details if mbx and mbx.protocols & MBX_COE else 0
    general[12:14] = struct.pack("<h", identity.ebus_current_ma)
    cats = _category(CAT_STRINGS, encoded) + _category(CAT_GENERAL, bytes(general))
    if identity.fmmus:
        cats += _category(CAT_FMMU, bytes(identity.fmmus))
    if identity.sync_managers:
        cats += _category(CAT_SM, b"".join(struct.pack("<HHBBBB", s.start, s.length, s.control, 0, s.enable, s.kind)
                                           for s in identity.sync_managers))
    if identity.tx_pdos:
        cats += _pdo_category(CAT_TXPDO, identity.tx_pdos)
    if identity.rx_pdos:
        cats += _pdo_category(CAT_RXPDO, identity.rx_pdos)
    cats += b"\xff\xff"
    start = 0x40 * 2
    if start + len(cats) > size_bytes:
        raise ValueError(f"SII of '{identity.name}' needs {start + len(cats)} bytes, EEPROM has {size_bytes}")
    words[start:start + len(cats)] = cats
    return words
