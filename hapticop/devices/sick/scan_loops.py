# cython: boundscheck=False, wraparound=False, annotation_typing=False
"""A scan telegram's numeric passes as single loops, for the compiled build: its hex values decoded,
its ranges scaled, its beam angles laid out.

numpy does each pass with a few whole-array calls: the hex decode alone is a dozen (811 values on a
TiM561). Warm, a call costs a microsecond or two. In the LIDAR's process, woken 15 times a second,
every call starts cold and costs about ten times that, and the calls were most of a scan's way to
the haptic loop (docs/realtime.md §4.15). Compiled (``scan_loops.pxd``), each pass is one loop with
no call inside. Interpreted, the loops would be far slower than numpy, so ``cola`` and ``scan`` use
them only when this module is compiled (``COMPILED``).

Both ways give the same result (tests/test_compiled_kernels.py). The decode gives the same values,
and for a bad channel the same error, found in the same order: too few tokens, then a byte that is
neither a hex digit nor a space, then an empty token, then one with too many digits. The ranges
and angles are the same IEEE double operations, in the same order, as numpy's.
"""

from __future__ import annotations

import importlib.machinery
import math

COMPILED = __file__.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES))
"""Whether this module runs compiled: only then is it faster than numpy."""

TOO_FEW = -1  # the body ends before `count` tokens
NOT_HEX = -2  # a byte of a token is neither a hex digit nor a space
EMPTY = -3  # two spaces in a row, or a space at either end
TOO_WIDE = -4  # a token has more than `digits` digits

NOT_A_DIGIT = 255  # CODES of a byte that is neither a hex digit nor the separator
SPACE_CODE = 16  # CODES of the separator
_NOT_A_DIGIT = NOT_A_DIGIT
_SPACE = 0x20
_NAN = math.nan
_LOW_32 = 0xFFFFFFFF  # a token too wide to decode still fits the output (it is refused anyway)


def _codes() -> bytes:
    table = bytearray([NOT_A_DIGIT]) * 256
    for value in range(16):
        table[ord("0123456789ABCDEF"[value])] = value
        table[ord("0123456789abcdef"[value])] = value
    table[_SPACE] = SPACE_CODE
    return bytes(table)


CODES = _codes()
"""Every byte's value as a hex digit (0-15), SPACE_CODE for the separator, NOT_A_DIGIT for anything else:
the one table both decodes read (``bytes.translate`` in cola's numpy passes, a lookup in ``decode_hex``)."""
_NIBBLE = CODES  # the same table, typed for the loop when compiled


def decode_hex(body, pos: int, count: int, digits: int, out) -> int:
    """Decode ``count`` space-separated hex tokens of ``body`` (bytes) from ``pos`` into ``out`` (uint32,
    contiguous, at least ``count`` long). Returns the position after the last token's space (the body's
    length + 1 at its end), or one of the negative codes above; ``out`` is then partly written."""
    if count > out.shape[0] or pos < 0:
        raise IndexError(f"{count} values from byte {pos} do not fit an output of {out.shape[0]}")
    end = len(body)
    nibble = _NIBBLE
    bad = False
    empty = False
    wide = False
    i = pos
    n = 0
    while True:
        start = i
        value = 0
        while i < end:
            char = body[i]
            if char == _SPACE:
                break
            digit = nibble[char]
            if digit == _NOT_A_DIGIT:
                bad = True
                digit = 0
            value = ((value << 4) | digit) & _LOW_32
            i += 1
        width = i - start
        if width == 0:
            empty = True
        elif width > digits:
            wide = True
        out[n] = value
        n += 1
        if n == count:
            break
        if i >= end:
            return TOO_FEW
        i += 1  # the space
    if bad:
        return NOT_HEX
    if empty:
        return EMPTY
    if wide:
        return TOO_WIDE
    return i + 1


def scale_ranges(raw, factor: float, offset: float, min_range: float, out) -> None:
    """``out = raw · factor (+ offset)``, NaN where below ``min_range``: metres from a DIST channel's raw
    values (``factor`` already divided by 1000). ``raw`` uint32 and ``out`` float64, contiguous, one length."""
    n = raw.shape[0]
    if out.shape[0] != n:
        raise IndexError(f"{n} raw values, {out.shape[0]} ranges")
    nan = _NAN
    for i in range(n):
        value = raw[i] * factor
        if offset != 0.0:
            value = value + offset
        out[i] = value if not value < min_range else nan


def beam_angles(start: float, step: float, out) -> None:
    """``out[i] = i · step + start``: each beam's angle (float64, contiguous)."""
    for i in range(out.shape[0]):
        value = i * step
        out[i] = value + start
