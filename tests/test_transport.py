"""One transport object per stream kind sizes a stream's buffers at start-up and when added live."""

import numpy as np

from hapticop.runtime.assembly import layout_of
from hapticop.runtime.region import Layout
from hapticop.runtime.system import ExitStatus
from hapticop.runtime.transport import LatestTransport, QueueTransport, transport_of
from hapticop.validation import validate_text

from .runtime_helpers import compose

BASE = """
version: 1
name: live
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, source, relay]}}
activities:
  mediator: {block: mediator}
  source: {block: counter}
  relay: {block: echo}
streams:
  count: {from: source.count, to: relay.input}
record: {}
"""
ACTIVITIES = "{probe: {block: echo}, other: {block: echo}, third: {block: echo}}"
SCHEDULE = "[mediator, source, relay, probe, other, third]"
TAP = "{from: relay.output, to: [probe.input, other.input], policy: {kind: queue, capacity: 8}}"
LAST = "{from: probe.output, to: third.input}"
STREAMS = f"{{tap: {TAP}, last: {LAST}}}"
PATCH = f"""
patches:
  plug:
    at: 100ms
    patch:
      activities: {ACTIVITIES}
      streams: {STREAMS}
      threads: {{main: {{schedules: {{0: {SCHEDULE}}}}}}}
"""


def declared() -> str:
    """The same system with the added streams there from the start."""
    text = BASE.replace("[mediator, source, relay]", SCHEDULE)
    text = text.replace("activities:\n", "activities:\n" + "".join(
        f"  {name}: {{block: echo}}\n" for name in ("probe", "other", "third")))
    return text.replace("streams:\n", f"streams:\n  tap: {TAP}\n  last: {LAST}\n")


def regions(layout: Layout) -> list[tuple[int, int, str]]:
    """Every placed piece of the region but the arena itself: (start, end, what)."""
    pieces = [(offset, offset + int(np.prod(shape)) * np.dtype(dtype).itemsize, name)
              for name, (offset, shape, dtype) in layout.sections.items() if name != "arena"]
    for name, transports in layout.transports.items():
        pieces += [(t.offset, t.offset + t.nbytes, f"stream {name} {t.reader}") for t in transports]
    pieces += [(t.offset, t.offset + t.nbytes, f"ring {name}") for name, t in layout.recorded.items()]
    return sorted(pieces)


def test_each_kind_has_its_transport_and_its_sizes():
    validated = validate_text(declared(), "t.yaml")
    loaded = validated.graph.loaded
    tap, count = transport_of(loaded, "tap"), transport_of(loaded, "count")
    assert isinstance(tap, QueueTransport) and isinstance(count, LatestTransport)
    assert [reader for _, reader in tap.buffers()] == ["probe.input", "other.input"]
    layout = layout_of(loaded, validated.flags, {"tap": 16})
    assert [t.nbytes for t in layout.transports["tap"]] == [n for n, _ in tap.buffers()]
    assert layout.recorded["tap"].nbytes == tap.ring_nbytes(16)
    assert "count" not in layout.recorded  # only what the observer reserved gets a ring


def test_a_stream_added_live_is_sized_as_at_start_up_and_overlaps_nothing(tmp_path):
    seen = {}
    result = compose(tmp_path, BASE + PATCH, duration="200ms", on_start=lambda system: seen.update(system=system))
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons
    live = seen["system"].layout
    assert {"tap", "last"} <= set(live.transports) and {"tap", "last"} <= set(live.recorded)

    # the same streams declared from the start: the same transport object sizes them the same
    validated = validate_text(declared(), "declared.yaml")
    start = layout_of(validated.graph.loaded, validated.flags, seen["system"].layout.rings)
    for name in ("tap", "last"):
        assert [t.nbytes for t in live.transports[name]] == [t.nbytes for t in start.transports[name]]
        assert live.recorded[name].nbytes == start.recorded[name].nbytes

    arena_start = live.sections["arena"][0]
    arena_end = arena_start + live.sections["arena"][1][0]
    for name in ("tap", "last"):  # taken from the room kept for live additions
        for t in [*live.transports[name], live.recorded[name]]:
            assert arena_start <= t.offset and t.offset + t.nbytes <= arena_end
    pieces = regions(live)
    for (_, end, what), (start_next, _, next_what) in zip(pieces, pieces[1:], strict=False):
        assert end <= start_next, f"{what} overlaps {next_what}"
    assert pieces[-1][1] <= live.size
