"""The Falcon's FTDI USB bridge as its host side sees it (docs/devices/falcon.md §1).

The driver and the virtual device share these numbers, so both speak the same vendor
requests: a request's meaning is written once. Only what libnifalcon uses is here: purges,
modem lines (DTR/RTS), flow control off, baud divisors, 8N1 and the latency timer.
"""

from __future__ import annotations

import enum

VENDOR_ID = 0x0403  # FTDI
PRODUCT_ID = 0xCB48  # Novint's own PID on an FTDI chip
PRODUCT = "FALCON HAPTIC"
INTERFACE = 0
EP_OUT = 0x02
EP_IN = 0x81
PACKET_SIZE = 64  # full-speed bulk packet: 2 status bytes + up to 62 data bytes
STATUS_BYTES = 2
VENDOR_OUT = 0x40  # bmRequestType: vendor, host to device, recipient device


class Request(enum.IntEnum):
    RESET = 0x00  # wValue 0 = SIO reset, 1 = purge RX, 2 = purge TX
    MODEM_CTRL = 0x01  # wValue high byte = lines to change, low byte = their levels
    FLOW_CTRL = 0x02
    BAUD = 0x03
    LINE = 0x04
    LATENCY = 0x09


PURGE_RX = 1
PURGE_TX = 2
DTR = 0x01
RTS = 0x02
DTR_LOW = DTR << 8
DTR_HIGH = DTR << 8 | DTR
RTS_LOW = RTS << 8
LINE_8N1 = 0x0008
FLOW_NONE = 0


class Baud(enum.IntEnum):
    """The three divisors libnifalcon sends (wValue; wIndex stays 0)."""

    LOADER = 0x4138  # 3 MHz / 312.5 = 9600 baud: the handshake
    UPLOAD = 0x0015  # 3 MHz / 21 = 142,857 baud: the firmware upload
    NORMAL = 0x0002  # 3 MHz / 2 = 1.5 Mbaud: 16-byte frames at 1 kHz


_FRACTION = (0.0, 0.5, 0.25, 0.125, 0.375, 0.625, 0.75, 0.875)


def baud_from_divisor(value: int, index: int = 0) -> float:
    """The baud rate an FT232R runs at for a divisor request (the device's side).

    n is wValue bits 0-13; a 3-bit fraction code sits in wValue bits 14-15 and wIndex bit 0.
    n = 0 and n = 1 are the chip's special cases, 3 and 2 Mbaud.
    """
    n = value & 0x3FFF
    code = (value >> 14) & 0x3 | (index & 0x1) << 2
    if n == 0:
        return 3_000_000.0
    if n == 1:
        return 2_000_000.0
    return 3_000_000.0 / (n + _FRACTION[code])
