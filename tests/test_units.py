import re

import pytest
from pydantic import BaseModel, ValidationError

from hapticop.composition.units import Duration, format_duration, format_period, parse_duration_ns


@pytest.mark.parametrize(
    "text, ns",
    [
        ("1ms", 1_000_000),
        ("15Hz", 66_666_667),
        ("66.667ms", 66_667_000),
        ("1kHz", 1_000_000),
        ("500us", 500_000),
        ("500µs", 500_000),
        ("2s", 2_000_000_000),
        ("250ns", 250),
        (" 1 ms ", 1_000_000),
        ("1e3us", 1_000_000),
        (".5ms", 500_000),
    ],
)
def test_parse(text, ns):
    assert parse_duration_ns(text) == ns


@pytest.mark.parametrize("text, fragment", [
    ("1", "'1' has no unit: write it with one of ns, us, ms, s, Hz or kHz, such as '1ms'"),
    ("1 parsec", "not a unit of time or rate"),
    ("0Hz", "rate of zero"),
    ("0.1ns", "shorter than one nanosecond"),
    ("-1ms", "'-1ms' is negative: a period or rate must be positive"),
    ("ms", "not a number followed by a unit"),
])
def test_parse_rejects(text, fragment):
    with pytest.raises(ValueError, match=re.escape(fragment)):
        parse_duration_ns(text)


@pytest.mark.parametrize("text, fragment", [
    ("5", "'5' has no unit: write it with one of ns, us, ms or s, such as '5s'"),
    ("5Hz", "'5Hz' is a rate; write a time (ns, us, ms or s)"),
    ("-2s", "'-2s' is negative: a duration must be positive"),
    ("2 parsecs", "'parsecs' is not a unit of time (ns, us, ms or s)"),
])
def test_a_time_alone_names_only_time_units(text, fragment):
    """A run's length (`--duration`) is a time: its messages never offer Hz or kHz."""
    with pytest.raises(ValueError, match=re.escape(fragment)):
        parse_duration_ns(text, rates=False)


class Holder(BaseModel):
    period: Duration


def test_model_requires_text_with_unit():
    with pytest.raises(ValidationError, match="needs a unit"):
        Holder(period=1)
    with pytest.raises(ValidationError, match="needs a unit"):
        Holder(period=True)
    assert Holder(period="15Hz").period == 66_666_667


def test_serialises_back_to_text():
    assert Holder(period="1ms").model_dump() == {"period": "1ms"}
    assert format_duration(66_666_667) == "66.6667ms"
    assert format_period(66_666_667) == "15Hz" and format_period(1_000_000) == "1ms"
    assert format_period(500_000) == "500us" and format_period(333_333_333) == "3Hz"
    assert format_duration(250) == "250ns"


def test_offsets_may_be_zero_but_periods_may_not():
    from pydantic import TypeAdapter, ValidationError

    from hapticop.composition.units import Duration, Offset

    offset = TypeAdapter(Offset)
    assert offset.validate_python("0ms") == 0 and offset.validate_python(0) == 0
    assert offset.validate_python("250us") == 250_000
    with pytest.raises(ValidationError):
        offset.validate_python("0Hz")
    with pytest.raises(ValidationError):
        TypeAdapter(Duration).validate_python("0ms")
