"""Beside the streams, a recording keeps each loop's timing (`/timing/THREAD`, JSON windows) and the
run's log records (`/log`, Foxglove's Log), read back with the mcap reader and decoded with the
schemas stored beside them (Foxglove's own, for the log)."""

from __future__ import annotations

import json

import jsonschema
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader

from hapticop.observe.timing_channels import WINDOW_NS
from hapticop.recording.mcapfile import LOG_TOPIC
from hapticop.runtime.logs import Level, format_line, parse_line

from .runtime_helpers import compose
from .test_recording import counters


@pytest.fixture(scope="module")
def counters_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("loops")
    result = compose(tmp, counters(), duration="2s")
    return tmp / "run-c", result


def _read(path, topic):
    with open(path, "rb") as stream:
        return [(schema, channel, message) for schema, channel, message in
                make_reader(stream).iter_messages(topics=[topic], log_time_order=False)]


def test_each_loop_has_its_timing_windows(counters_run):
    run_dir, result = counters_run
    for thread, activities in (("main", {"mediator", "counter", "echo"}), ("slow", {"slow_counter", "slow_echo"})):
        found = _read(run_dir / "c.mcap", f"/timing/{thread}")
        schema, channel, _ = found[0]
        assert (schema.encoding, channel.message_encoding, channel.metadata["thread"]) == ("jsonschema", "json", thread)
        windows = [json.loads(message.data) for *_, message in found]
        for window in windows:
            jsonschema.validate(window, json.loads(schema.data))
            assert set(window["compute_max_us"]) == activities and window["missed"] == 0
        assert [m.sequence for *_, m in found] == sorted(m.sequence for *_, m in found)
        published = [m.publish_time for *_, m in found]
        gaps = [b - a for a, b in zip(published[:-1], published[1:], strict=True)]
        assert all(gap >= WINDOW_NS for gap in gaps[:-1]) and 0 < gaps[-1]  # the last window ends with the run
        assert [round(w["window_s"] * 1e9) for w in windows[1:]] == gaps
        # every cycle after the first window's start is in exactly one window
        total = result.timing["threads"][thread]["cycles"]
        assert 0 < sum(w["cycles"] for w in windows) <= total
        assert sum(w["cycles"] for w in windows) >= total * (1 - 2 * WINDOW_NS / 2e9)


def test_the_runs_log_records_are_foxgloves_log_messages(counters_run):
    run_dir, _ = counters_run
    messages = pytest.importorskip("foxglove.messages")
    schema = messages.Log.get_schema()
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(schema.data).file:
        pool.Add(file)
    log_class = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    found = _read(run_dir / "c.mcap", LOG_TOPIC)
    assert found and {s.name for s, *_ in found} == {"foxglove.Log"}
    recorded = [(log_class.FromString(m.data), m.publish_time) for *_, m in found]
    in_files = set()
    for path in run_dir.glob("*.log"):
        for line in path.read_text().splitlines():
            stamp, level, text = parse_line(line)
            in_files.add((path.stem, stamp, text))
    as_recorded = {(r.name, stamp, r.message) for r, stamp in recorded}
    assert as_recorded <= in_files and {"system", "counter"} <= {name for name, *_ in as_recorded}
    assert all(r.timestamp.seconds * 10**9 + r.timestamp.nanos == stamp for r, stamp in recorded)


def test_a_log_line_reads_back_as_written():
    line = format_line(12_345_678_901, Level.WARNING, "a message: 3 > 2")
    assert parse_line(line.rstrip("\n")) == (12_345_679_000, Level.WARNING, "a message: 3 > 2")  # to the microsecond
    assert parse_line("  a second line of a message") is None
