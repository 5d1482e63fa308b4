"""Durations and rates written the way engineers write them: `1ms`, `15Hz`, `66.667ms`.

Compositions state cycle times either as a period or as a frequency. Both become one
integer number of nanoseconds, the unit `clock_nanosleep` works in, so nothing downstream
ever compares floats of mixed units.
"""

from __future__ import annotations

import re
from typing import Annotated, Any

from pydantic import BeforeValidator, PlainSerializer, WithJsonSchema
from pydantic_core import PydanticCustomError

NS_PER_UNIT = {"ns": 1, "us": 1_000, "µs": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
HZ_PER_UNIT = {"Hz": 1.0, "kHz": 1_000.0}
UNITS_TEXT = "ns, us, ms, s, Hz or kHz"
TIME_UNITS_TEXT = "ns, us, ms or s"

_QUANTITY = re.compile(r"^\s*(?P<number>[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][-+]?[0-9]+)?\s*(?P<unit>[A-Za-zµ]+)\s*$")
_NUMBER = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)([eE][-+]?[0-9]+)?")


def parse_duration_ns(text: str, allow_zero: bool = False, rates: bool = True) -> int:
    """Parse `1ms`, `66.667ms` or `15Hz` into whole nanoseconds (rounded to the nearest);
    `allow_zero` accepts a zero time (`0ms`) for offsets, never a zero rate; without `rates`
    only a time is accepted (a run's length is no frequency)."""
    units = UNITS_TEXT if rates else TIME_UNITS_TEXT
    match = _QUANTITY.match(text.strip().removeprefix("-"))
    if match and text.strip().startswith("-"):
        least = "zero or more" if allow_zero else "positive"
        raise ValueError(f"'{text}' is negative: a {'duration' if allow_zero or not rates else 'period or rate'} "
                         f"must be {least}")
    if not match:
        if _NUMBER.match(text) and not text.strip().rstrip("0123456789.eE+-"):
            raise ValueError(f"'{text}' has no unit: write it with one of {units}, such as "
                             f"'{text.strip()}{'ms' if rates else 's'}'")
        raise ValueError(f"'{text}' is not a number followed by a unit ({units})")
    number = float(_NUMBER.match(text).group(0))
    unit = match.group("unit")
    if unit in NS_PER_UNIT:
        ns = number * NS_PER_UNIT[unit]
    elif unit in HZ_PER_UNIT and rates:
        if number == 0:
            raise ValueError(f"'{text}' is a rate of zero; a cycle needs a positive rate")
        ns = 1e9 / (number * HZ_PER_UNIT[unit])
    elif unit in HZ_PER_UNIT:
        raise ValueError(f"'{text}' is a rate; write a time ({units}), such as '5s'")
    else:
        raise ValueError(f"'{unit}' is not a unit of {'time or rate' if rates else 'time'} ({units})")
    if ns < 1 and not (allow_zero and ns == 0 and unit in NS_PER_UNIT):
        raise ValueError(f"'{text}' is shorter than one nanosecond")
    return round(ns)


def format_duration(ns: int) -> str:
    """The shortest faithful text for a duration, for messages and reports."""
    for unit, scale in (("s", 10**9), ("ms", 10**6), ("us", 10**3)):
        if ns >= scale:
            return f"{ns / scale:.6g}{unit}"
    return f"{ns}ns"


def format_period(ns: int) -> str:
    """A thread's period as people write it: 1ms, or 15Hz when it is a whole rate, not a round time."""
    hz = 1e9 / ns
    if ns % 1000 and abs(hz - round(hz)) < 1e-6 * hz:
        return f"{round(hz)}Hz"
    return format_duration(ns)


def _coerce_offset(value: Any) -> int:
    if value == 0 and not isinstance(value, bool):
        return 0
    if isinstance(value, str):
        try:
            return parse_duration_ns(value, allow_zero=True)
        except ValueError as error:
            raise PydanticCustomError("duration", "{reason}", {"reason": str(error)}) from None
    return _coerce_duration(value)


def _coerce_duration(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, str):
        raise PydanticCustomError(
            "duration_unit",
            "a duration needs a unit: write it as text such as '1ms', '66.667ms' or '15Hz' "
            "(got {value})",
            {"value": repr(value)},
        )
    try:
        return parse_duration_ns(value)
    except ValueError as error:
        raise PydanticCustomError("duration", "{reason}", {"reason": str(error)}) from None


# A duration in nanoseconds, written in YAML with its unit.
Duration = Annotated[
    int,
    BeforeValidator(_coerce_duration),
    PlainSerializer(format_duration, return_type=str),
    WithJsonSchema(
        {
            "type": "string",
            "pattern": r"^\s*([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][-+]?[0-9]+)?\s*(ns|us|µs|ms|s|Hz|kHz)\s*$",
            "description": "a period or a rate with its unit: '1ms', '66.667ms', '15Hz', '1kHz'",
            "examples": ["1ms", "15Hz", "66.667ms"],
        }
    ),
]

# A time offset that may be zero ('0ms' or 0): a phase, a busy-wait allowance.
Offset = Annotated[
    int,
    BeforeValidator(_coerce_offset),
    PlainSerializer(format_duration, return_type=str),
    WithJsonSchema(
        {
            "anyOf": [
                {"type": "string",
                 "pattern": r"^\s*([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][-+]?[0-9]+)?\s*(ns|us|µs|ms|s)\s*$"},
                {"const": 0},
            ],
            "description": "a time with its unit, or 0: '0ms', '250us', 0",
            "examples": ["0ms", "250us"],
        }
    ),
]
