"""Recording streams to MCAP: every sample read back with the mcap reader, under the virtual clock
(exact counts) and on the wall clock (a recorder killed, stalled, or outliving its parent)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from ruamel.yaml import YAML
from typer.testing import CliRunner

from hapticop.blocks.interface import Port
from hapticop.cli.main import app, bare_options
from hapticop.observe.recorder import RecordedRing, Recorder, RecorderPlan, values
from hapticop.recording.mcapfile import RecordingFile, StreamInfo, part_of
from hapticop.recording.reading import RecordingError, contents, series
from hapticop.recording.recover import recover
from hapticop.runtime.streams import SpscQueue, queue_nbytes, sample_dtype

from .conftest import ROOT
from .runtime_helpers import compose

# A counter on the 1 kHz main thread and one on a 100 Hz thread: each publishes once per cycle it
# runs, so each sample's value is known from its number (count = number, slow = 2 x number).
COUNTERS = """
version: 1
threads:
  main: {period: 1ms, deploy: main, schedules: {0: [mediator, counter, echo]}}
  slow: {period: 10ms, deploy: DEPLOY, schedules: {0: [slow_counter, slow_echo]}}
activities:
  mediator: {block: mediator}
  counter: {block: counter}
  echo: {block: echo}
  slow_counter: {block: counter, params: {step: 2}}
  slow_echo: {block: echo}
streams:
  count: {from: counter.count, to: echo.input}
  slow: {from: slow_counter.count, to: [slow_echo.input], policy: {kind: queue, capacity: 4}}
RECORD
"""


def counters(record: str = "record: {}", deploy: str = "thread") -> str:
    return COUNTERS.replace("RECORD", record).replace("DEPLOY", deploy)


def _messages(path, topic):
    with open(path, "rb") as stream:
        return [(m.sequence, m.publish_time, m.log_time, m.data)
                for _, _, m in make_reader(stream).iter_messages(topics=[topic], log_time_order=False)]


def _check_stream(path, name, scale, exactly=None):
    """Sequences contiguous from 1, publish times increasing, each payload its number x scale."""
    found = series(path, name)
    n = len(found.sequence)
    if exactly is not None:
        assert n == exactly and found.values[-1] == scale * exactly  # the last value: the cycles counted
    assert n > 0
    assert np.array_equal(found.sequence, np.arange(1, n + 1))
    assert (np.diff(found.publish_ns) > 0).all()
    assert (found.log_ns >= found.publish_ns).all()
    assert np.array_equal(found.values, scale * found.sequence)
    return found


# -- the virtual clock: exact ---------------------------------------------------------------

def test_every_sample_is_recorded_with_its_number_stamp_and_value(tmp_path):
    result = compose(tmp_path, counters(), duration="2s")
    path = tmp_path / "run-c" / "c.mcap"
    assert result.recording["path"] == str(path) and path.exists() and not part_of(path).exists()
    n, slow = (result.recording["streams"][s]["written"] for s in ("count", "slow"))
    cycles = result.timing["threads"]
    assert 1900 < n <= cycles["main"]["cycles"] and 190 < slow <= cycles["slow"]["cycles"]
    assert result.recording["streams"]["count"] == {"written": n, "recorded": n, "dropped": 0}
    assert result.recording["streams"]["slow"] == {"written": slow, "recorded": slow, "dropped": 0}
    _check_stream(path, "count", 1, exactly=n)  # the counter ran n cycles, one sample each
    _check_stream(path, "slow", 2, exactly=slow)
    found = contents(path)
    cycles_of = {f"cycles/{a}" for a in ("mediator", "counter", "echo", "slow_counter", "slow_echo")}
    assert found.drops() == {"count": 0, "slow": 0, **dict.fromkeys(cycles_of, 0)}  # each activity's cycles too
    written = found.metadata["hapticop.written"]
    assert {k: written[k] for k in ("count", "slow")} == {"count": str(n), "slow": str(slow)}
    assert int(written["cycles/counter"]) >= n  # a row each step, configuring and cleaning too
    assert found.metadata["hapticop.run"]["clock"] == "virtual"
    channel = {c.topic: c for c in found.channels}["/streams/count"]
    assert channel.count == n and channel.schema == "hapticop.Int64Array"
    assert (channel.stream.dtype, channel.stream.shape, channel.stream.unit, channel.stream.rate_hz) == (
        "int64", (), "1", 1000.0)
    assert channel.stream.writer == "counter.count" and channel.stream.readers == ("echo.input",)
    tree = YAML(typ="safe").load(found.attachments["composition.yaml"])
    assert tree["streams"]["count"]["from"] == "counter.count" and "record" in tree
    params = json.loads(found.attachments["parameters.json"])
    assert params["counter"]["step"] == 1 and params["slow_counter"]["step"] == 2


def test_a_stream_nobody_reads_is_recorded_all_the_same(tmp_path):
    """A stream without `to:` (as a network bridge's link figures are) is valid, has its buffers and its
    recorder ring like any other, of either kind, and records every sample."""
    text = counters().replace("schedules: {0: [mediator, counter, echo]}",
                              "schedules: {0: [mediator, counter, echo, watched, queued]}").replace(
        "activities:\n", "activities:\n  watched: {block: counter, params: {step: 3}}\n"
        "  queued: {block: counter, params: {step: 4}}\n").replace(
        "streams:\n", "streams:\n  unread: {from: watched.count}\n"
        "  unread_queue: {from: queued.count, to: [], policy: {kind: queue, capacity: 4}}\n")
    result = compose(tmp_path, text, duration="1s")
    path = tmp_path / "run-c" / "c.mcap"
    n = result.recording["streams"]["unread"]["written"]
    assert n > 900 and result.recording["streams"]["unread_queue"]["written"] == n
    _check_stream(path, "unread", 3, exactly=n)
    _check_stream(path, "unread_queue", 4, exactly=n)
    assert {c.topic: c for c in contents(path).channels}["/streams/unread"].stream.readers == ()


def test_a_recording_is_the_same_every_run(tmp_path):
    first = compose(tmp_path, counters(), duration="1s", name="a")
    second = compose(tmp_path, counters(), duration="1s", name="b")
    assert first.recording["streams"] == second.recording["streams"]
    a, b = (_messages(tmp_path / f"run-{n}" / f"{n}.mcap", "/streams/slow") for n in "ab")
    assert a == b  # numbers, publish and log times, payloads


def test_the_payloads_decode_with_protobufs_own_parser_and_the_stored_schema(tmp_path):
    compose(tmp_path, counters(), duration="1s")
    with open(tmp_path / "run-c" / "c.mcap", "rb") as stream:
        for schema, channel, message in make_reader(stream).iter_messages(topics=["/streams/slow"]):
            assert schema.encoding == "protobuf" and channel.message_encoding == "protobuf"
            files = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
            pool = descriptor_pool.DescriptorPool()
            for file in files.file:
                pool.Add(file)
            decoded = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(message.data)
            assert list(decoded.data) == [2 * message.sequence]


def test_chosen_streams_only_and_decimated(tmp_path):
    result = compose(tmp_path, counters("record: {streams: [count], decimate: {count: 10}}"), duration="1s")
    path = tmp_path / "run-c" / "c.mcap"
    found = contents(path)
    assert [c.topic for c in found.channels if c.stream and "cycles/" not in c.topic] == ["/streams/count"]
    assert {c.topic for c in found.channels if c.stream and "cycles/" in c.topic} == {  # what replay lines up by
        f"/streams/cycles/{a}" for a in ("mediator", "counter", "echo", "slow_counter", "slow_echo")}
    assert {c.topic for c in found.channels if not c.stream} == {"/timing/main", "/timing/slow", "/log",
                                                                 "/events/flags", "/events/lifecycle"}  # the loops'
    assert found.channels[0].stream.every == 10
    sequence = [m[0] for m in _messages(path, "/streams/count")]
    written = result.recording["streams"]["count"]["written"]
    assert written > 900 and sequence == list(range(10, written + 1, 10))


def test_nothing_is_recorded_unless_asked(tmp_path):
    result = compose(tmp_path, counters(record=""), duration="200ms")
    assert result.recording is None and not list((tmp_path / "run-c").glob("*.mcap*"))


def test_compose_record_records_a_file_that_says_nothing_of_it(tmp_path):
    from hapticop.composition.units import parse_duration_ns
    from hapticop.runtime.system import RunOptions, run_system
    from hapticop.validation import validate_path

    path = tmp_path / "c.yaml"
    path.write_text(counters(record=""))
    target = tmp_path / "elsewhere" / "x.mcap"
    result = run_system(validate_path(path), RunOptions(clock="virtual", duration_ns=parse_duration_ns("1s"),
                                                        run_dir=tmp_path / "run", echo=False, record=str(target)))
    assert result.recording["path"] == str(target)
    _check_stream(target, "count", 1, exactly=result.recording["streams"]["count"]["written"])


def test_the_record_option_may_stand_alone():
    assert bare_options(["compose", "c.yaml", "--record"]) == ["compose", "c.yaml", "--record", ""]
    assert bare_options(["compose", "--record", "c.yaml"]) == ["compose", "--record", "", "c.yaml"]
    assert bare_options(["compose", "--record", "--seed", "1", "c.yaml"])[2] == ""
    assert bare_options(["compose", "c.yaml", "--record", "x.mcap"]) == [
        "compose", "c.yaml", "--record", "x.mcap"]


# -- the command line: info, plot, recover ---------------------------------------------------

def test_info_plot_and_csv(tmp_path):
    result = compose(tmp_path, counters(), duration="1s")
    n, slow = (result.recording["streams"][s]["written"] for s in ("count", "slow"))
    path = tmp_path / "run-c" / "c.mcap"
    runner = CliRunner()
    shown = runner.invoke(app, ["info", str(path)])
    assert shown.exit_code == 0, shown.output
    assert "/streams/count" in shown.output and str(n) in shown.output and "int64[] [1]" in shown.output
    assert "composition.yaml, parameters.json" in shown.output
    table = tmp_path / "out.csv"
    exported = runner.invoke(app, ["plot", str(path), "count", "slow", "--csv", str(table)])
    assert exported.exit_code == 0, exported.output
    rows = table.read_text().splitlines()
    assert rows[0] == "stream,sequence,publish_time_s,log_time_s,value[0]" and len(rows) == 1 + n + slow
    assert rows[1].startswith("count,1,0.000000000,") and rows[1].endswith(",1.0")
    picture = tmp_path / "out.png"
    drawn = runner.invoke(app, ["plot", str(path), "count", "slow[0]", "-o", str(picture)])
    assert drawn.exit_code == 0, drawn.output
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    unknown = runner.invoke(app, ["plot", str(path), "cont"])
    assert unknown.exit_code == 1 and "no stream or topic 'cont'" in unknown.output


def test_info_refuses_an_unfinished_file_with_advice(tmp_path):
    broken = tmp_path / "x.mcap.part"
    broken.write_bytes(b"\x89MCAP0\r\n" + b"\x01" * 40)
    with pytest.raises(RecordingError, match="hapticop recover"):
        contents(broken)
    not_mcap = tmp_path / "y.mcap"
    not_mcap.write_text("hello")
    result = CliRunner().invoke(app, ["info", str(not_mcap)])
    assert result.exit_code == 1 and "not a finished MCAP recording" in result.output


def _cut(source, target, keep_bytes):
    target.write_bytes(source.read_bytes()[:keep_bytes])


def test_recover_keeps_every_whole_chunk_and_says_what_was_lost(tmp_path):
    """A file cut where a kill would cut it: inside the chunk after the last flush."""
    path = tmp_path / "whole.mcap"
    file = RecordingFile(path)
    info = StreamInfo("x", "float64", (3,), "m", 1000.0)
    channel = file.stream_channel(info)
    ring = _ring(Port("float64", (3,), "m"), 4096)
    batch = np.zeros(4096, sample_dtype(ring.port))
    for k in range(1, 3001):
        ring.push(np.full(3, float(k)), 1000 * k)
    flushed_at = None
    for part in range(3):
        n = ring.drain_into(batch[:1000])
        file.write_samples(channel, batch[:n], 10**9 * (part + 1))
        if part == 1:
            file.flush()  # two flushed chunks; the third still being written
            flushed_at = file.part.stat().st_size
    file.flush()
    whole = file.part.stat().st_size
    file.abandon()
    damaged = tmp_path / "run.mcap.part"
    _cut(file.part, damaged, flushed_at + (whole - flushed_at) // 10)  # inside the third chunk
    found = recover(damaged)
    assert found.target == tmp_path / "run.mcap" and not found.complete
    assert found.messages == {"/streams/x": 2000} and found.lost_bytes > 0
    assert "lost: the last" in "\n".join(found.describe())
    recovered = series(found.target, "x")
    assert np.array_equal(recovered.sequence, np.arange(1, 2001))
    assert np.array_equal(recovered.values[:, 0], np.arange(1, 2001))
    with pytest.raises(FileExistsError):
        recover(damaged)
    runner = CliRunner()
    again = runner.invoke(app, ["recover", str(damaged), "-o", str(tmp_path / "again.mcap")])
    assert again.exit_code == 3 and "recovered 2000 messages" in again.output
    empty = tmp_path / "empty.mcap.part"
    empty.write_bytes(b"")
    assert runner.invoke(app, ["recover", str(empty)]).exit_code == 1


def test_recovering_a_finished_file_loses_nothing(tmp_path):
    result = compose(tmp_path, counters(), duration="1s")
    n, slow = (result.recording["streams"][s]["written"] for s in ("count", "slow"))
    found = recover(tmp_path / "run-c" / "c.mcap", tmp_path / "copy.mcap")
    original = {c.topic: c.count for c in contents(tmp_path / "run-c" / "c.mcap").channels}
    assert original["/streams/count"] == n and original["/streams/slow"] == slow
    assert found.complete and found.messages == original  # the streams', the loops' timing and the log's
    drops = contents(tmp_path / "copy.mcap").drops()
    assert drops["count"] == drops["slow"] == 0 and not any(drops.values())  # the activities' cycles' too


# -- the rings and views, without a system ---------------------------------------------------

def _ring(port, capacity):
    buffer = np.zeros(queue_nbytes(port, capacity) + 64, np.uint8)
    start = (-buffer.ctypes.data) % 64
    return SpscQueue(buffer[start:start + queue_nbytes(port, capacity)], port, capacity, "drop_oldest")


def test_a_drained_ring_gives_samples_in_order_and_counts_what_was_overwritten():
    port = Port("float64", (2,), "m")
    ring = _ring(port, 8)
    batch = np.zeros(8, sample_dtype(port))
    for k in range(1, 21):
        ring.push(np.array([k, -k], float), 100 * k)
    assert ring.drain_into(batch) == 8 and ring.dropped == 12 and ring.written == 20
    assert batch["count"].tolist() == list(range(13, 21)) and batch["stamp_ns"][0] == 1300
    assert np.array_equal(batch["payload"].view(np.float64)[:, 0], np.arange(13, 21))
    assert ring.drain_into(batch) == 0
    ring.push(np.zeros(2), 1)
    ring._slots[20 % 8].words[0] += 1  # a writer caught mid-sample: odd sequence word
    assert ring.drain_into(batch) == 0 and ring.dropped == 13


class NormView:
    """A derived channel: the length of a 3-vector stream, as a view would add it."""

    streams = frozenset({"x"})

    def start(self, file, streams):
        self.file = file
        self.channel = file.channel("/derived/norm", "json", file.schema("norm", "jsonschema", b"{}"), {})
        self.info = streams["x"]

    def samples(self, info, samples, log_time_ns):
        for number, stamp, value in zip(samples["count"], samples["stamp_ns"], values(info, samples), strict=True):
            self.file.write(self.channel, log_time_ns, json.dumps({"norm": float(np.linalg.norm(value))}).encode(),
                            int(stamp), int(number))

    def finish(self):
        self.finished = True


def test_views_derive_channels_from_the_drained_batches(tmp_path):
    port = Port("float64", (3,), "m")
    capacity = 64
    nbytes = queue_nbytes(port, capacity)
    region = np.zeros(nbytes + 64, np.uint8)
    offset = (-region.ctypes.data) % 64
    writer = SpscQueue(region[offset:offset + nbytes], port, capacity)
    view = NormView()
    plan = RecorderPlan(tmp_path / "v.mcap", [RecordedRing(StreamInfo("x", "float64", (3,), "m", 1000.0), offset,
                                                           nbytes, capacity)], "virtual", views=[view])
    reader = SpscQueue(region[offset:offset + nbytes], port, capacity)
    now = [0]
    recorder = Recorder(plan, {"x": reader}, lambda: now[0])
    for k in range(1, 51):
        writer.push(np.array([3.0 * k, 4.0 * k, 0.0]), k)
    now[0] = 100
    recorder.drain()
    summary = recorder.finish()
    assert summary["streams"]["x"] == {"written": 50, "recorded": 50, "dropped": 0} and view.finished
    norms = [json.loads(m[3])["norm"] for m in _messages(tmp_path / "v.mcap", "/derived/norm")]
    assert norms == [5.0 * k for k in range(1, 51)]


# -- the wall clock: the recorder is a process of its own ------------------------------------

def _pids_children(pid):
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as stat:
                    if int(stat.read().rsplit(")", 1)[1].split()[1]) == pid:
                        found.append(int(entry))
            except OSError:
                continue
    return found


def test_in_real_time_every_sample_reaches_the_file(tmp_path):
    result = compose(tmp_path, counters(), clock="realtime", duration="2s")
    assert result.outcome.status == 0, result.outcome.reasons
    path = tmp_path / "run-c" / "c.mcap"
    streams = result.recording["streams"]
    assert streams["count"]["dropped"] == 0 and streams["slow"]["dropped"] == 0
    _check_stream(path, "count", 1, exactly=streams["count"]["written"])
    _check_stream(path, "slow", 2, exactly=streams["slow"]["written"])
    assert contents(path).metadata["hapticop.run"]["clock"] == "CLOCK_MONOTONIC"


def _running_for(system, cycles):
    """Wait until the main loop has run this many cycles."""
    index = system.layout.thread_index["main"]
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and system.region.cycles[index] < cycles:
        time.sleep(0.01)


def test_a_stalled_recorder_drops_counted_samples_and_never_holds_the_loops(tmp_path):
    """SIGSTOP the recorder for longer than its rings hold: the loops go on publishing every
    cycle; what the recorder lost is exactly the gaps in the file, and it says so."""
    stalled = {}

    def stall(system):
        def act():
            _running_for(system, 500)
            os.kill(system.observer.recorder.pid, signal.SIGSTOP)
            stalled["stopped"] = True
            time.sleep(1.2)
            os.kill(system.observer.recorder.pid, signal.SIGCONT)

        threading.Thread(target=act, daemon=True).start()

    record = "record: {depth: 200ms}"
    result = compose(tmp_path, counters(record), clock="realtime", duration="4s", on_start=stall)
    assert stalled and result.outcome.status == 0, result.outcome.reasons
    count = result.recording["streams"]["count"]
    assert count["dropped"] > 0 and count["recorded"] + count["dropped"] == count["written"]
    found = series(tmp_path / "run-c" / "c.mcap", "count")
    assert len(found.sequence) == count["recorded"]
    assert int(np.sum(np.diff(found.sequence) - 1)) + (int(found.sequence[0]) - 1) == count["dropped"]
    assert np.array_equal(found.values, found.sequence)  # what was kept is whole
    assert found.values[-1] == count["written"]  # the counter published every one of its cycles, stall or not
    assert contents(tmp_path / "run-c" / "c.mcap").drops()["count"] == count["dropped"]


def test_a_killed_recorder_leaves_a_part_that_recovers(tmp_path):
    killed = {}

    def kill(system):
        def act():
            _running_for(system, 1500)  # cycles: more than a flush's worth of samples are in the file
            killed["pid"] = system.observer.recorder.pid
            os.kill(system.observer.recorder.pid, signal.SIGKILL)

        threading.Thread(target=act, daemon=True).start()

    result = compose(tmp_path, counters(), clock="realtime", duration="3500ms", on_start=kill)
    assert killed
    assert result.recording is None and any("recorder" in r and "recover" in r for r in result.outcome.reasons)
    path = tmp_path / "run-c" / "c.mcap"
    assert part_of(path).exists() and not path.exists()
    found = recover(part_of(path))
    assert not found.complete and found.messages["/streams/count"] > 0  # flushed every second
    recovered = _check_stream(path, "count", 1)
    _check_stream(path, "slow", 2)
    assert "hapticop.drops" not in contents(path).metadata and len(recovered.sequence) < 3500


def test_when_the_main_process_is_killed_the_recorder_finishes_the_file(tmp_path):
    """SIGKILL of the main process alone: the recorder is told by the kernel, takes what the
    rings still hold and finishes a valid file, then leaves."""
    composition = tmp_path / "c.yaml"
    composition.write_text(counters())
    target = tmp_path / "k.mcap"
    process = subprocess.Popen([sys.executable, "-m", "hapticop.cli", "compose", str(composition), "--run-dir",
                                str(tmp_path / "run"), "--record", str(target)], cwd=ROOT,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and (not part_of(target).exists() or part_of(target).stat().st_size < 2000):
            time.sleep(0.05)
        recorders = [p for p in _pids_children(process.pid) if "record_main" in _cmdline(p) or _spawned(p)]
        time.sleep(1.0)
    finally:
        process.kill()
        process.wait(timeout=10)
    assert recorders
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not target.exists():
        time.sleep(0.05)
    assert target.exists() and not part_of(target).exists()
    _check_stream(target, "count", 1)
    assert contents(target).drops()["count"] == 0


def _cmdline(pid):
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as cmdline:
            return cmdline.read().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _spawned(pid):
    line = _cmdline(pid)
    return "multiprocessing.spawn" in line and "resource_tracker" not in line


def test_under_the_virtual_clock_the_rings_are_drained_between_main_cycles(tmp_path):
    """Rings a tenth of the run deep lose nothing: the main process drains them as the run goes."""
    result = compose(tmp_path, counters("record: {depth: 100ms}"), duration="1s")
    streams = result.recording["streams"]
    assert streams["count"]["written"] > 900 and streams["count"]["dropped"] == 0
    assert streams["count"]["recorded"] == streams["count"]["written"] and streams["slow"]["dropped"] == 0
