"""The live view (`compose --view`): a client speaking Foxglove's WebSocket protocol, on loopback,
sees every channel advertised, subscribes, and decodes what arrives, the scan with the protobuf
descriptor Foxglove's own SDK ships."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import socket
import struct
import threading
import time
from pathlib import Path

import pytest
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from hapticop.recording.live import LiveOptions
from hapticop.recording.mcapfile import LOG_TOPIC
from hapticop.recording.scene import ARROW_TOPIC, FRAMES_TOPIC, SCAN_TOPIC
from hapticop.runtime.system import RunOptions, run_system
from hapticop.validation import validate_path

from .conftest import ROOT
from .runtime_helpers import PATIENCE_S

messages = pytest.importorskip("foxglove.messages")
websockets = pytest.importorskip("websockets.asyncio.client")

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


def _message_class(schema_name: str, file_descriptor_set: bytes):
    pool = descriptor_pool.DescriptorPool()
    for file in descriptor_pb2.FileDescriptorSet.FromString(file_descriptor_set).file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))


async def _watch(address: str, enough, seen: dict) -> None:
    """Connect, gather the advertised channels, subscribe to all, and keep every message by topic
    until `enough(seen)` (then tell the caller) and the server closes the connection."""
    async with websockets.connect(address, subprotocols=[SUBPROTOCOL], max_size=None) as socket:
        subscriptions = {}
        async for frame in socket:
            if isinstance(frame, str):
                op = json.loads(frame)
                seen.setdefault("ops", []).append(op["op"])
                if op["op"] == "advertise":
                    fresh = [c for c in op["channels"] if c["id"] not in seen.setdefault("channels", {})]
                    for channel in fresh:
                        seen["channels"][channel["id"]] = channel
                        subscriptions[len(subscriptions) + 1] = channel["topic"]
                    await socket.send(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": sid, "channelId": c["id"]} for sid, c in zip(
                            range(len(subscriptions) - len(fresh) + 1, len(subscriptions) + 1), fresh, strict=True)]}))
                continue
            assert frame[0] == MESSAGE_DATA
            subscription, stamp = struct.unpack_from("<IQ", frame, 1)
            seen.setdefault("messages", {}).setdefault(subscriptions[subscription], []).append((stamp, frame[13:]))
            if enough(seen):
                seen.setdefault("enough", time.monotonic())
    seen["closed"] = True


def _live_run(tmp_path, text: str, enough, name: str):
    """A wall-clock run with the live view on a free loopback port, watched by `_watch` until it has
    `enough`; then the run is shut down, and the client keeps what the last drain sends."""
    path = tmp_path / f"{name}.yaml"
    path.write_text(text)
    seen: dict = {}

    def client(system) -> None:
        def watch() -> None:
            deadline = time.monotonic() + PATIENCE_S
            while getattr(system.observer.recorder, "address", None) is None and time.monotonic() < deadline:
                time.sleep(0.02)
            stopper = threading.Thread(target=_stop_when, args=(system, seen, deadline), daemon=True)
            stopper.start()
            try:
                asyncio.run(asyncio.wait_for(_watch(system.observer.recorder.address, enough, seen), PATIENCE_S + 10))
            except Exception as error:  # noqa: BLE001 - reported by the test
                seen["error"] = repr(error)
                system.request_shutdown()

        threading.Thread(target=watch, daemon=True).start()

    options = RunOptions(clock="realtime", duration_ns=int((PATIENCE_S + 5) * 1e9), run_dir=tmp_path / f"run-{name}",
                         echo=False, view=LiveOptions(port=0))
    result = run_system(validate_path(path), options, on_start=client)
    deadline = time.monotonic() + 10
    while "ops" in seen and "closed" not in seen and "error" not in seen and time.monotonic() < deadline:
        time.sleep(0.05)  # the client reads the last messages
    return result, seen


def _stop_when(system, seen: dict, deadline: float) -> None:
    while "enough" not in seen and "error" not in seen and time.monotonic() < deadline:
        time.sleep(0.02)
    system.request_shutdown()


def _topics(seen: dict) -> dict[str, dict]:
    return {c["topic"]: c for c in seen.get("channels", {}).values()}


def _all_but_the_log_sent(seen: dict) -> bool:
    advertised = set(_topics(seen)) - {LOG_TOPIC}
    return bool(advertised) and advertised <= set(seen.get("messages", {}))


@pytest.fixture(scope="module")
def hallway_live(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("live")
    text = (ROOT / "systems" / "hallway.yaml").read_text()
    result, seen = _live_run(tmp, text, _all_but_the_log_sent, "hallway")
    return tmp, result, seen



def _another(token: str) -> str:
    """A token one character off the run's: never the run's own (a token may well start with 'x')."""
    return ("y" if token[0] == "x" else "x") + token[1:]

def test_every_channel_is_advertised_and_sends(hallway_live):
    tmp, result, seen = hallway_live
    missing = set(_topics(seen)) - set(seen.get("messages", {}))
    assert "error" not in seen and "enough" in seen, (seen.get("error"), missing)
    assert result.outcome.status == 0, result.outcome.reasons
    assert seen["ops"][0] == "serverInfo"
    composition = validate_path(tmp / "hallway.yaml").graph.loaded.composition
    expected = ({f"/streams/{name}" for name in composition.streams} | {f"/timing/{t}" for t in composition.threads}
                | {SCAN_TOPIC, FRAMES_TOPIC, ARROW_TOPIC, LOG_TOPIC, "/events/flags", "/events/lifecycle"})
    topics = _topics(seen)
    assert set(topics) == expected
    assert expected - {LOG_TOPIC} <= set(seen["messages"])
    assert result.recording["path"] is None and not list((tmp / "run-hallway").glob("*.mcap*"))  # shown, not written
    assert result.recording["view"]["sent"] >= len(seen["messages"])


def test_the_scan_decodes_with_foxgloves_own_schema(hallway_live):
    _, _, seen = hallway_live
    channel = _topics(seen)[SCAN_TOPIC]
    assert (channel["encoding"], channel["schemaName"], channel["schemaEncoding"]) == (
        "protobuf", "foxglove.LaserScan", "protobuf")
    schema = messages.LaserScan.get_schema()
    scan_class = _message_class(schema.name, schema.data)  # Foxglove's descriptor, not the advertised one
    for stamp, data in seen["messages"][SCAN_TOPIC]:
        scan = scan_class.FromString(data)
        assert scan.frame_id == "laser" and len(scan.ranges) > 100 and scan.end_angle > scan.start_angle
        assert stamp == scan.timestamp.seconds * 1_000_000_000 + scan.timestamp.nanos  # the loop's stamp


def test_a_stream_decodes_with_its_advertised_schema_and_is_thinned_for_display(hallway_live):
    _, _, seen = hallway_live
    channel = _topics(seen)["/streams/handle_position"]
    array_class = _message_class(channel["schemaName"], base64.b64decode(channel["schema"]))
    sent = seen["messages"]["/streams/handle_position"]
    assert all(len(array_class.FromString(data).data) == 3 for _, data in sent)
    stamps = [stamp for stamp, _ in sent]
    assert stamps == sorted(stamps)
    gaps = sorted(b - a for a, b in zip(stamps[:-1], stamps[1:], strict=True))
    assert gaps[len(gaps) // 2] >= 0.9e9 / LiveOptions().rate_hz  # a 1 kHz stream, sent at about the display rate


def test_loop_timing_and_log_records_arrive(hallway_live):
    _, _, seen = hallway_live
    timing = [json.loads(data) for _, data in seen["messages"]["/timing/main"]]
    assert all(t["cycles"] > 0 and t["latency_max_us"] >= t["latency_p99_us"] >= t["latency_p50_us"] for t in timing)
    assert "haptic" in timing[-1]["compute_max_us"]  # the haptic controller, on the main loop
    schema = messages.Log.get_schema()
    log_class = _message_class(schema.name, schema.data)
    records = [log_class.FromString(data) for _, data in seen["messages"].get(LOG_TOPIC, [])]
    assert records and all(r.name and r.message for r in records)  # the shutdown's records, at least


def test_recorded_and_shown_at_once(tmp_path):
    """With a file to record to, the live view is a second output: the file keeps every sample."""
    from hapticop.recording.reading import series

    from .test_recording import counters

    def some_counts(seen: dict) -> bool:
        return len(seen.get("messages", {}).get("/streams/count", [])) >= 5

    result, seen = _live_run(tmp_path, counters(), some_counts, "c")
    missing = set(_topics(seen)) - set(seen.get("messages", {}))
    assert "error" not in seen and "enough" in seen, (seen.get("error"), missing)
    recording = result.recording
    assert recording["path"] == str(tmp_path / "run-c" / "c.mcap") and recording["streams"]["count"]["dropped"] == 0
    assert len(series(recording["path"], "count").sequence) == recording["streams"]["count"]["written"]
    shown = [int.from_bytes(data[-8:], "little") for _, data in seen["messages"]["/streams/count"]]  # int64 counts
    assert shown == sorted(set(shown)) and shown[-1] <= recording["streams"]["count"]["written"]


def test_without_the_sdk_view_says_so_in_one_line(tmp_path, monkeypatch):
    import sys

    from typer.testing import CliRunner

    from hapticop.cli.main import app, bare_options

    monkeypatch.setitem(sys.modules, "foxglove", None)  # as if the [foxglove] extra were not installed
    path = tmp_path / "c.yaml"
    path.write_text("version: 1\n")
    result = CliRunner().invoke(app, ["compose", str(path), "--view", ""])
    assert result.exit_code == 2
    assert result.output.strip() == "hapticop: the live view needs foxglove-sdk: pip install 'hapticop[foxglove]'"
    assert bare_options(["compose", "c.yaml", "--view"]) == ["compose", "c.yaml", "--view", ""]
    assert bare_options(["compose", "--view", "9000", "c.yaml"])[2] == "9000"


def test_a_running_system_is_shown_from_outside_without_being_touched(tmp_path):
    """`hapticop view`: the control socket says where the region is; a viewer of its own reads the
    latest slots, timing and logs, and leaves every queue ring to its reader."""
    from hapticop.control.client import request
    from hapticop.observe.viewer import Attachment, view

    from .control_helpers import while_running
    from .test_recording import counters

    seen: dict = {}

    def work(socket, system) -> None:
        answer = request(str(socket), {"op": "attach"}, timeout=10)
        assert answer["ok"] and answer["attach"]["region"] == system.region.name
        addresses, stop, summary = [], threading.Event(), {}
        viewer = threading.Thread(target=lambda: summary.update(view(
            Attachment(**answer["attach"]), LiveOptions(port=0), lambda line: addresses.append(line.split()[4]),
            stop.is_set)), daemon=True)
        viewer.start()
        deadline = time.monotonic() + PATIENCE_S
        while not addresses and time.monotonic() < deadline:
            time.sleep(0.02)

        def enough(seen: dict) -> bool:
            got = seen.get("messages", {})
            return len(got.get("/streams/count", [])) >= 5 and "/timing/main" in got

        client = threading.Thread(target=lambda: asyncio.run(asyncio.wait_for(
            _watch(addresses[0], enough, seen), PATIENCE_S)), daemon=True)
        client.start()
        while "enough" not in seen and time.monotonic() < deadline:
            time.sleep(0.02)
        stop.set()
        viewer.join(timeout=10)
        client.join(timeout=10)
        assert summary["streams"]["count"]["written"] > 0 and "slow" not in summary["streams"]

    while_running(tmp_path, work, counters(record=""), ready="counter")
    assert "enough" in seen
    topics = set(_topics(seen))
    assert {"/streams/count", "/timing/main", "/timing/slow", LOG_TOPIC} <= topics
    assert "/streams/slow" not in topics  # a queue stream's rings have their own readers
    shown = [int.from_bytes(data[-8:], "little") for _, data in seen["messages"]["/streams/count"]]
    assert shown == sorted(set(shown)) and shown[0] > 0


def _identity(tmp_path):
    """A self-signed certificate for 127.0.0.1 and its PKCS#8 key, made here."""
    import subprocess

    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                    "-keyout", str(key), "-out", str(cert), "-days", "1", "-subj", "/CN=127.0.0.1",
                    "-addext", "subjectAltName=IP:127.0.0.1"], check=True, capture_output=True, timeout=60)
    return cert, key


async def _first_op(address: str, **options) -> str:
    async with websockets.connect(address, subprotocols=[SUBPROTOCOL], open_timeout=PATIENCE_S, **options) as socket:
        return json.loads(await asyncio.wait_for(socket.recv(), PATIENCE_S))["op"]


def test_with_a_certificate_the_view_speaks_tls_only(tmp_path):
    import ssl

    from hapticop.recording.live import LiveServer

    cert, key = _identity(tmp_path)
    server = LiveServer(LiveOptions(port=0, tls_cert=str(cert), tls_key=str(key)))
    try:
        assert server.address.startswith("wss://127.0.0.1:")
        trusting = ssl.create_default_context(cafile=str(cert))
        assert asyncio.run(_first_op(server.address, ssl=trusting)) == "serverInfo"
        with pytest.raises(Exception):  # noqa: B017, PT011 - any refusal: the handshake never completes in the clear
            asyncio.run(_first_op(server.address.replace("wss://", "ws://"), open_timeout=10))
    finally:
        server.stop()


def test_a_view_beyond_loopback_says_at_start_who_can_watch(tmp_path):
    from typer.testing import CliRunner

    from hapticop.cli.main import app
    from hapticop.recording.live import exposure

    assert exposure(LiveOptions(host="127.0.0.1")) is None and exposure(LiveOptions(host="::1")) is None
    assert exposure(LiveOptions(host="localhost")) is None
    said = exposure(LiveOptions(host="0.0.0.0", port=9000))
    assert "anyone who can reach this machine on any of its networks, at port 9000" in said
    assert "if they hold the run's token" in said and "in the clear" in said
    cert, key = _identity(tmp_path)
    assert "over TLS" in exposure(LiveOptions(host="192.0.2.7", tls_cert=str(cert), tls_key=str(key)))

    runner = CliRunner()
    result = runner.invoke(app, ["view", str(tmp_path / "no-such-system"), "--host", "0.0.0.0", "--port", "0"])
    assert result.exit_code in (1, 2) and "no-such-system" in result.output  # then it finds no system
    lines = result.output.splitlines()
    assert lines[0].startswith("hapticop: warning: the live view serves every stream to anyone who can reach this "
                               "machine"), result.output
    result = runner.invoke(app, ["view", str(tmp_path / "no-such-system"), "--port", "0"])
    assert "warning" not in result.output
    result = runner.invoke(app, ["view", "x", "--tls-cert", str(cert)])
    assert result.exit_code == 2 and "both a TLS certificate and its key" in result.output
    result = runner.invoke(app, ["view", "x", "--tls-cert", str(cert), "--tls-key", str(tmp_path / "absent.pem")])
    assert result.exit_code == 2 and "cannot read its TLS identity" in result.output
    assert "Traceback" not in result.output


async def _refused(address: str, **options) -> int:
    """The HTTP status a handshake was refused with (the client never gets a WebSocket)."""
    from websockets.exceptions import InvalidStatus

    try:
        async with websockets.connect(address, subprotocols=[SUBPROTOCOL], open_timeout=PATIENCE_S, **options):
            return 101
    except InvalidStatus as refusal:
        return refusal.response.status_code


def test_the_view_lets_in_only_a_client_with_the_runs_token(tmp_path):
    """The token is written owner-only in the run directory; without it, or with another, the handshake is
    refused; with it the client is served. A client that sends garbage, or opens and never finishes its
    request, or connects and never reads, holds back no one: a good client is served meanwhile."""
    import socket

    from hapticop.recording.live import LiveServer

    server = LiveServer(LiveOptions(port=0), run_dir=tmp_path)
    try:
        token = server.token_file.read_text().strip()
        assert server.token_file.stat().st_mode & 0o777 == 0o600
        assert server.address == f"{server.public_address}/?token={token}"
        assert asyncio.run(_refused(server.public_address)) == 401
        assert asyncio.run(_refused(f"{server.public_address}/?token={_another(token)}")) == 401
        assert asyncio.run(_refused(f"{server.public_address}/?token=")) == 401
        assert server.gate.refused == 3
        host, port = server.public_address.removeprefix("ws://").rsplit(":", 1)
        stalled = [socket.create_connection((host, int(port))) for _ in range(3)]
        stalled[0].sendall(b"\x00\xff" * 5000)  # garbage, longer than a request may be
        stalled[1].sendall(b"GET /?token=")  # a request never finished
        reader = socket.create_connection((host, int(port)))  # the token, then never reads
        reader.sendall(f"GET /?token={token} HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                       "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
                       f"Sec-WebSocket-Protocol: {SUBPROTOCOL}\r\n\r\n".encode())
        assert asyncio.run(_first_op(server.address)) == "serverInfo"
        for s in [*stalled, reader]:
            s.close()
    finally:
        server.stop()


def test_a_run_served_live_writes_its_token_where_only_its_owner_reads(tmp_path):
    """`compose --view`: the token file lies in the run directory, and the address the run gives carries it."""
    from .test_recording import counters

    _, seen = _live_run(tmp_path, counters(), lambda seen: "messages" in seen, "token")
    assert "error" not in seen, seen.get("error")
    files = list((tmp_path / "run-token").glob("live-view-*.token"))
    assert len(files) == 1 and files[0].stat().st_mode & 0o777 == 0o600


async def _subscribe_all(socket) -> None:
    while True:
        op = json.loads(await socket.recv())
        if op["op"] == "advertise":
            await socket.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": n, "channelId": c["id"]} for n, c in enumerate(op["channels"], 1)]}))
            return


def test_a_client_that_stops_reading_holds_back_neither_the_writer_nor_a_good_client(tmp_path):
    """Through the gate, a subscribed client that reads nothing fills its socket; the writer's calls go on
    returning and another client keeps receiving."""
    from hapticop.recording.live import LiveServer

    server = LiveServer(LiveOptions(port=0, rate_hz=1000), run_dir=tmp_path)
    channel = server.channel("/big", "json", 0, {})
    stop = threading.Event()
    writes = [0]

    def write() -> None:
        payload = b"x" * 65536
        while not stop.is_set():
            writes[0] += 1
            server.write(channel, 0, payload, time.monotonic_ns(), writes[0])
            time.sleep(0.001)

    async def clients() -> int:
        async with websockets.connect(server.address, subprotocols=[SUBPROTOCOL], max_queue=1, max_size=None) as slow:
            await _subscribe_all(slow)  # then never reads again
            async with websockets.connect(server.address, subprotocols=[SUBPROTOCOL], max_size=None) as good:
                await _subscribe_all(good)
                received, deadline = 0, time.monotonic() + PATIENCE_S
                while received < 200 and time.monotonic() < deadline:
                    frame = await asyncio.wait_for(good.recv(), PATIENCE_S)
                    received += isinstance(frame, bytes)
                return received

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    try:
        before = writes[0]
        assert asyncio.run(clients()) >= 200
        assert writes[0] > before + 200  # the writer went on while the slow client read nothing
    finally:
        stop.set()
        writer.join(timeout=PATIENCE_S)
        server.stop()
    assert not writer.is_alive(), "the writer stalled"


def _run_processes() -> list[int]:
    """This process and its descendants: a run's main process, its recorder and its loops' processes."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            parents[int(entry.name)] = int(stat.rsplit(")", 1)[1].split()[1])
    found, frontier = [os.getpid()], [os.getpid()]
    while frontier:
        frontier = [pid for pid, parent in parents.items() if parent in frontier]
        found += frontier
    return found


def _listening(pids: list[int]) -> set[tuple[str, int]]:
    """Every TCP socket these processes listen on, as (address to connect to, port): their socket inodes
    looked up in /proc/net/tcp and tcp6."""
    inodes = set()
    for pid in pids:
        try:
            for fd in Path(f"/proc/{pid}/fd").iterdir():
                with contextlib.suppress(OSError):
                    target = os.readlink(fd)
                    if target.startswith("socket:["):
                        inodes.add(target[8:-1])
        except OSError:
            continue
    found = set()
    for table, family in (("/proc/net/tcp", socket.AF_INET), ("/proc/net/tcp6", socket.AF_INET6)):
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != "0A" or fields[9] not in inodes:  # 0A: LISTEN
                continue
            address, port = fields[1].split(":")
            raw = b"".join(int(address[k:k + 8], 16).to_bytes(4, "little") for k in range(0, len(address), 8))
            host = socket.inet_ntop(family, raw)
            if host in ("0.0.0.0", "::"):
                host = "127.0.0.1" if family == socket.AF_INET else "::1"
            found.add((f"[{host}]" if family == socket.AF_INET6 else host, int(port, 16)))
    return found


async def _served(url: str) -> bool:
    """Whether a Foxglove client gets the protocol's first message there."""
    try:
        return await asyncio.wait_for(_first_op(url), PATIENCE_S * 2) == "serverInfo"
    except Exception:  # noqa: BLE001 - any refusal: 401, a closed socket, no WebSocket at all
        return False


async def _dropped_after(address: str, *sent) -> int | None:
    """The close code a client gets after sending `sent` (None: it was never closed)."""
    from websockets.exceptions import ConnectionClosed

    async with websockets.connect(address, subprotocols=[SUBPROTOCOL], open_timeout=PATIENCE_S,
                                  max_size=None) as socket_:
        for message in sent:
            await socket_.send(message)
        try:
            while True:
                await asyncio.wait_for(socket_.recv(), PATIENCE_S)
        except ConnectionClosed as closed:
            return closed.rcvd.code if closed.rcvd else None
        except TimeoutError:
            return None


def test_no_socket_of_the_run_serves_the_view_without_the_token_and_hostile_clients_are_dropped(tmp_path):
    """Every TCP socket the run's processes listen on (found in /proc, not taken from the run's word)
    refuses a client without the run's token or with another; with the token, the gate serves. Clients
    that send garbage, a binary frame, a subscription to a channel there is not, or a message of 1 MiB are
    closed, and the run goes on: a good client still receives, and the run ends well."""
    from .test_recording import counters

    seen: dict = {}

    def probe(system) -> None:
        def work() -> None:
            try:
                deadline = time.monotonic() + PATIENCE_S
                while getattr(system.observer.recorder, "address", None) is None and time.monotonic() < deadline:
                    time.sleep(0.02)
                address = system.observer.recorder.address
                public, token = address.split("/?token=")
                sockets = _listening(_run_processes())
                seen["sockets"] = sockets
                seen["gate"] = (public.removeprefix("ws://").rsplit(":", 1)[0], int(public.rsplit(":", 1)[1]))
                seen["served"] = {s: [asyncio.run(_served(f"ws://{s[0]}:{s[1]}{path}"))
                                      for path in ("/", f"/?token={_another(token)}", "/?token=")] for s in sockets}
                seen["with token"] = asyncio.run(_served(address))
                if any(any(tries) for tries in seen["served"].values()):
                    return  # the hole: said below, before the rest is tried
                seen["closes"] = [asyncio.run(_dropped_after(address, *sent)) for sent in (
                    ["not json"], [b"\x01\x00\x00\x00\x00"], ['{"op": "subscribe", "subscriptions": '
                                                            '[{"id": 1, "channelId": 999999}]}'],
                    ['{"op": "advertise", "channels": []}'], ["x" * (1 << 20)])]
                threading.Thread(target=_stop_when, args=(system, seen, time.monotonic() + PATIENCE_S),
                                 daemon=True).start()  # once the good client has enough
                asyncio.run(asyncio.wait_for(_watch(address, lambda s: len(
                    s.get("messages", {}).get("/streams/count", [])) >= 5, seen), PATIENCE_S))
            except Exception as error:  # noqa: BLE001 - reported by the test
                seen["error"] = repr(error)
            finally:
                system.request_shutdown()

        threading.Thread(target=work, daemon=True).start()

    path = tmp_path / "c.yaml"
    path.write_text(counters())
    options = RunOptions(clock="realtime", duration_ns=int((PATIENCE_S * 4) * 1e9), run_dir=tmp_path / "run",
                         echo=False, view=LiveOptions(port=0))
    result = run_system(validate_path(path), options, on_start=probe)
    assert not any(any(tries) for tries in seen.get("served", {}).values()), seen["served"]
    assert "error" not in seen, (seen["error"], seen.get("closes"))
    assert result.outcome.status == 0, result.outcome.reasons
    assert seen["gate"] in seen["sockets"] and seen["with token"]
    assert seen["closes"] == [1008, 1008, 1008, 1008, 1009]
    assert len(seen["messages"]["/streams/count"]) >= 5
