"""CoLa A, the ASCII dialect of SICK's TiM5xx: framing, values and tokens.

A telegram is STX (0x02), a body of tokens separated by single spaces, ETX (0x03); no length,
no checksum. Integers travel as uppercase hex without leading zeros, Reals as their 8-digit
IEEE-754 bit pattern, strings as a hex length then the raw characters (which may hold spaces).

Everything that decodes bytes from the wire raises `ColaError` and nothing else, whatever the
bytes are: a scanner (or a broken network) may send anything, and the caller only has to
count and skip. A refusal from the device (`sFA <code>`) is the subclass `ColaDeviceError`.
The scan telegram, built from these values and read with `TokenReader`, is `scan.py`'s;
requests, replies and the start-up commands are `commands.py`'s.
"""

from __future__ import annotations

import re
import struct

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.sick import scan_loops

STX = 0x02
ETX = 0x03
LEVEL3_HASH = "F4724744"  # "Authorized client": md5-fold of "client"

# ---------------------------------------------------------------------------------------------
# errors


class ColaError(ValueError):
    """A telegram that cannot be decoded, or a device reply that says no."""


class ColaDeviceError(ColaError):
    """The device answered `sFA <code>`: it understood the frame and refused the request."""

    def __init__(self, code: int, request: str | None = None):
        self.code = code
        self.request = request
        name, hint = SFA_CODES.get(code, ("UNKNOWN", "code not in SICK's list"))
        about = f" to {request!r}" if request else ""
        super().__init__(f"device refused{about}: sFA {code:X} = {name} ({hint})")


SFA_CODES: dict[int, tuple[str, str]] = {
    0x1: ("METHODIN_ACCESSDENIED", "method needs a higher user level: log in first"),
    0x2: ("METHODIN_UNKNOWNINDEX", "unknown method name"),
    0x3: ("VARIABLE_UNKNOWNINDEX", "unknown variable name"),
    0x4: ("LOCALCONDITIONFAILED", "value out of range for this device"),
    0x5: ("INVALID_DATA", "invalid data (deprecated code)"),
    0x6: ("UNKNOWN_ERROR", "unknown error (deprecated code)"),
    0x7: ("BUFFER_OVERFLOW", "the reply would not fit"),
    0x8: ("BUFFER_UNDERFLOW", "too few parameters"),
    0x9: ("ERROR_UNKNOWN_TYPE", "internal: unknown type"),
    0xA: ("VARIABLE_WRITE_ACCESSDENIED", "write needs a higher user level, or the variable is read-only"),
    0xB: ("UNKNOWN_CMD_FOR_NAMESERVER", "name not understood"),
    0xC: ("UNKNOWN_COLA_COMMAND", "bad command type (not sRN/sWN/sMN/sEN/...)"),
    0xD: ("METHODIN_SERVER_BUSY", "a method call is still running"),
    0xE: ("FLEX_OUT_OF_BOUNDS", "array too long"),
    0xF: ("EVENTREG_UNKNOWNINDEX", "unknown event"),
    0x10: ("COLA_A_VALUE_OVERFLOW", "number too big for the field"),
    0x11: ("COLA_A_INVALID_CHARACTER", "bad character in a number"),
    0x12: ("OSAI_NO_MESSAGE", "internal"),
    0x13: ("OSAI_NO_ANSWER_MESSAGE", "internal"),
    0x14: ("INTERNAL", "internal"),
    0x15: ("HubAddressCorrupted", "internal"),
    0x16: ("HubAddressDecoding", "internal"),
    0x17: ("HubAddressAddressExceeded", "internal"),
    0x18: ("HubAddressBlankExpected", "internal"),
    0x19: ("AsyncMethodsAreSuppressed", "internal"),
    0x20: ("ComplexArraysNotSupported", "internal"),
}

# ---------------------------------------------------------------------------------------------
# framing


def frame(body: bytes | str) -> bytes:
    """STX + body + ETX; the body may not contain either delimiter (there is no escaping)."""
    data = body.encode("latin-1") if isinstance(body, str) else bytes(body)
    if b"\x02" in data or b"\x03" in data:
        raise ValueError("a CoLa A body cannot contain STX (0x02) or ETX (0x03)")
    return b"\x02" + data + b"\x03"


def unframe(telegram: bytes) -> bytes:
    """The body of exactly one framed telegram."""
    data = bytes(telegram)
    if len(data) < 2 or data[0] != STX or data[-1] != ETX:
        raise ColaError("not a CoLa A telegram: it must start with STX (0x02) and end with ETX (0x03)")
    body = data[1:-1]
    if b"\x02" in body or b"\x03" in body:
        raise ColaError("more than one telegram, or a broken one: STX/ETX inside the body")
    return body


# ---------------------------------------------------------------------------------------------
# values (§2.1)

_HEX_TOKEN = re.compile(rb"[0-9A-Fa-f]+\Z")
_DEC_TOKEN = re.compile(rb"[+-][0-9]+\Z")
_REAL_TOKEN = re.compile(rb"[0-9A-Fa-f]{8}\Z")
CONTROL_BYTES = re.compile(rb"[\x00-\x1f]")


def encode_uint(value: int, bits: int = 32) -> bytes:
    """Uppercase hex without leading zeros (zero is `0`), as the device sends it."""
    if not 0 <= value < 1 << bits:
        raise ValueError(f"{value} does not fit an unsigned {bits}-bit field")
    return b"%X" % value


def decode_uint(token: bytes, bits: int = 32, what: str = "value") -> int:
    """Hex, leading zeros accepted (the device accepts them too); range-checked."""
    if not _HEX_TOKEN.match(token) or len(token) > 16:
        raise ColaError(f"{what}: {show_token(token)} is not a hex number")
    value = int(token, 16)
    if value >> bits:
        raise ColaError(f"{what}: {show_token(token)} does not fit {bits} bits")
    return value


def encode_int32(value: int) -> bytes:
    """Hex of the two's-complement pattern: -450000 becomes `FFF92230`."""
    if not -(1 << 31) <= value < 1 << 31:
        raise ValueError(f"{value} does not fit a signed 32-bit field")
    return b"%X" % (value & 0xFFFFFFFF)


def decode_int32(token: bytes, what: str = "value") -> int:
    """Two's-complement hex, or decimal with an explicit sign (`-450000`), which SICK accepts."""
    if _DEC_TOKEN.match(token) and len(token) <= 12:
        value = int(token, 10)
        if not -(1 << 31) <= value < 1 << 31:
            raise ColaError(f"{what}: {show_token(token)} does not fit a signed 32-bit field")
        return value
    raw = decode_uint(token, 32, what)
    return raw - (1 << 32) if raw & 0x80000000 else raw


def encode_real(value: float) -> bytes:
    """The float32 bit pattern as exactly 8 uppercase hex digits: 1.0 is `3F800000`."""
    return struct.pack(">f", value).hex().upper().encode()


def decode_real(token: bytes, what: str = "value") -> float:
    if not _REAL_TOKEN.match(token):
        raise ColaError(f"{what}: {show_token(token)} is not a Real (exactly 8 hex digits)")
    return struct.unpack(">f", bytes.fromhex(token.decode()))[0]


def encode_string(text: bytes | str) -> bytes:
    """Hex length, a space, the raw characters. An empty string is just `0` (our guess)."""
    data = text.encode("latin-1") if isinstance(text, str) else bytes(text)
    if not data:
        return b"0"
    return encode_uint(len(data), 16) + b" " + data


def show_token(token: bytes, limit: int = 24) -> str:
    """A token as an error message quotes it: repr'd, cut after `limit` bytes."""
    text = token[:limit].decode("latin-1")
    return repr(text + ("…" if len(token) > limit else ""))


# Vectorised hex for value blocks: bytes.translate maps every byte of the body to its nibble
# (0..15), a space to 16 and anything else to 255, in C; numpy then works on those codes.
_SPACE_CODE = scan_loops.SPACE_CODE
_BAD_CODE = scan_loops.NOT_A_DIGIT
_CODE_TABLE = scan_loops.CODES


def _bad_channel(problem: int, what: str, count: int, digits: int, tokens: int = 0) -> ColaError:
    """What is wrong with a channel's values (a `scan_loops` code), in words; both decodes say it so."""
    return ColaError({scan_loops.TOO_FEW: f"{what}: {count} values announced, the telegram ends after {tokens} tokens",
                      scan_loops.NOT_HEX: f"{what}: a value is not a hex number",
                      scan_loops.EMPTY: f"{what}: empty value (double space)",
                      scan_loops.TOO_WIDE: f"{what}: a value has more than {digits} hex digits"}[problem])


# ---------------------------------------------------------------------------------------------
# reading tokens


class TokenReader:
    """A cursor over a body: one token, one number or one length-prefixed string at a time.

    Never splits the whole body on spaces, because strings may contain spaces; uses the counts
    the telegram carries instead (docs/devices/sick-tim561.md's parser advice, §4).
    """

    __slots__ = ("body", "pos", "end", "_spaces", "_codes")

    def __init__(self, body: bytes, pos: int = 0):
        self.body = body
        self.pos = pos
        self.end = len(body)
        self._spaces: NDArray[np.intp] | None = None
        self._codes: NDArray[np.uint8] | None = None

    @property
    def at_end(self) -> bool:
        return self.pos == self.end + 1 or (self.pos == 0 and self.end == 0)

    def token(self, what: str) -> bytes:
        if self.pos > self.end:
            raise ColaError(f"telegram ends before {what}")
        stop = self.body.find(b" ", self.pos)
        if stop < 0:
            stop = self.end
        token = self.body[self.pos:stop]
        if not token:
            raise ColaError(f"empty token at byte {self.pos} ({what}): a double, leading or trailing space")
        self.pos = stop + 1
        return token

    def uint(self, bits: int, what: str) -> int:
        return decode_uint(self.token(what), bits, what)

    def int32(self, what: str) -> int:
        return decode_int32(self.token(what), what)

    def real(self, what: str) -> float:
        return decode_real(self.token(what), what)

    def flag(self, what: str) -> bool:
        value = self.uint(16, what)
        if value > 1:
            raise ColaError(f"{what}: expected 0 or 1, got {value}")
        return value == 1

    def string(self, what: str) -> bytes:
        length = self.uint(16, f"length of {what}")
        if length == 0:
            return b""
        stop = self.pos + length
        if stop > self.end:
            raise ColaError(f"{what}: {length} characters announced, {max(self.end - self.pos, 0)} left")
        if stop < self.end and self.body[stop] != 0x20:
            raise ColaError(f"{what}: no space after its {length} characters")
        text = self.body[self.pos:stop]
        self.pos = stop + 1
        return text

    def rest(self) -> bytes:
        """Everything not read yet (the parameters of a reply)."""
        return self.body[self.pos:] if self.pos <= self.end else b""

    def expect_end(self, what: str) -> None:
        if not self.at_end:
            raise ColaError(f"unexpected data after {what}: {show_token(self.body[self.pos:])}")

    def values(self, count: int, digits: int, what: str) -> NDArray[np.uint32]:
        """`count` hex tokens of at most `digits` digits, decoded in one numpy pass."""
        if count == 0:
            return np.empty(0, np.uint32)
        if self.pos > self.end:
            raise ColaError(f"telegram ends before {what}")
        if scan_loops.COMPILED:
            return self._values_compiled(count, digits, what)
        if self._codes is None:
            self._codes = np.frombuffer(self.body.translate(_CODE_TABLE), dtype=np.uint8)
            self._spaces = np.flatnonzero(self._codes == _SPACE_CODE)
        spaces, codes = self._spaces, self._codes
        first = int(spaces.searchsorted(self.pos))
        available = len(spaces) - first
        ends = np.empty(count, dtype=np.intp)
        if available >= count:
            ends[:] = spaces[first:first + count]
        elif available == count - 1:
            ends[:-1] = spaces[first:]
            ends[-1] = self.end
        else:
            raise _bad_channel(scan_loops.TOO_FEW, what, count, digits, available + 1)
        last = int(ends[-1])
        if last > self.pos and codes[self.pos:last].max() == _BAD_CODE:  # (an empty first token is below)
            raise _bad_channel(scan_loops.NOT_HEX, what, count, digits)
        widths = np.empty(count, dtype=np.intp)
        widths[0] = ends[0] - self.pos
        np.subtract(ends[1:], ends[:-1], out=widths[1:])
        widths[1:] -= 1
        if widths.min() < 1:
            raise _bad_channel(scan_loops.EMPTY, what, count, digits)
        if widths.max() > digits:
            raise _bad_channel(scan_loops.TOO_WIDE, what, count, digits)
        ends -= 1  # now the last digit of each token
        values = codes[ends].astype(np.uint32)
        near_start = int(ends[0]) < digits  # keep the indexes of padding digits inside the body
        for place in range(1, digits):  # digit `place` from the right, where the token has one
            ends -= 1
            if near_start:
                np.maximum(ends, 0, out=ends)
            digit = codes[ends].astype(np.uint32)
            digit *= widths > place
            digit <<= 4 * place
            values += digit
        self.pos = last + 1
        return values

    def _values_compiled(self, count: int, digits: int, what: str) -> NDArray[np.uint32]:
        """The same decode as one compiled loop (scan_loops.py): the same values, the same errors."""
        values = np.empty(count, np.uint32)
        after = scan_loops.decode_hex(self.body, self.pos, count, digits, values)
        if after >= 0:
            self.pos = after
            return values
        raise _bad_channel(after, what, count, digits, self.body.count(b" ", self.pos) + 1)
