"""`hapticop devices`: the LIDAR probe against the TiM561 simulator on loopback, and the CLI."""

from __future__ import annotations

import json
import socket
import threading

import pytest
from typer.testing import CliRunner

from hapticop.cli import app
from hapticop.devices.sick.probe import ProbeError, probe_lidar
from hapticop.devices.sick.simulator import TiMSimulator

runner = CliRunner()


@pytest.fixture
def tim():
    with TiMSimulator(serial_number=0x1078AAA) as sim:
        sim.start()
        yield sim


def _closed_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


class _OneShotServer:
    """Accepts one connection on loopback, answers the first request with `reply`, then closes."""

    def __init__(self, reply: bytes | None) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.reply = reply
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        conn, _ = self.listener.accept()
        with conn:
            if self.reply is not None:
                conn.recv(1024)
                conn.sendall(self.reply)

    def __enter__(self) -> _OneShotServer:
        return self

    def __exit__(self, *exc) -> None:
        self.thread.join(5)
        self.listener.close()


def test_probe_reads_identity_serial_and_state(tim):
    found = probe_lidar("127.0.0.1", tim.port)
    assert (found.device_type, found.firmware) == ("TiM561", "V2.51-21.08.15")
    assert found.serial == str(0x1078AAA) and found.state == "ready"


def test_a_silent_scanner_is_named_with_the_cola_b_hint(tim):
    tim.mute()
    with pytest.raises(ProbeError, match=r"did not answer the CoLa A identity request `sRI 0` within 0.2 s.*CoLa B"):
        probe_lidar("127.0.0.1", tim.port, timeout_s=0.2)


def test_nothing_listening_is_a_refused_connection():
    port = _closed_port()
    with pytest.raises(ProbeError, match=f"127.0.0.1:{port} refused the connection: .*nothing listens"):
        probe_lidar("127.0.0.1", port)


def test_a_peer_that_hangs_up_is_explained():
    with _OneShotServer(None) as server, pytest.raises(ProbeError, match="closed the connection"):
        probe_lidar("127.0.0.1", server.port)


def test_a_peer_that_is_not_a_scanner_is_explained():
    with _OneShotServer(b"\x02HTTP/1.1 400 Bad Request\x03") as server, \
            pytest.raises(ProbeError, match="answered, but not as a CoLa A scanner: unknown reply type"):
        probe_lidar("127.0.0.1", server.port)


def test_a_refusal_is_reported_with_its_sfa_code():
    with _OneShotServer(b"\x02sFA 2\x03") as server, \
            pytest.raises(ProbeError, match="refused the identity request: .*METHODIN_UNKNOWNINDEX"):
        probe_lidar("127.0.0.1", server.port)


def test_cli_probes_a_lidar_without_usb(tim):
    result = runner.invoke(app, ["devices", "--no-usb", "--lidar", f"127.0.0.1:{tim.port}"])
    assert result.exit_code == 0, result.output
    assert f"LIDAR 127.0.0.1:{tim.port}: TiM561, firmware V2.51-21.08.15, serial {0x1078AAA}, state ready" \
        in result.output


def test_cli_reports_an_unreachable_lidar_and_a_bad_address():
    port = _closed_port()
    result = runner.invoke(app, ["devices", "--no-usb", "--lidar", f"127.0.0.1:{port}", "--lidar", "host:abc"])
    assert result.exit_code == 1
    assert "refused the connection" in result.output and "'host:abc' is not HOST or HOST:PORT" in result.output


def test_cli_lists_a_virtual_falcon_as_json():
    result = runner.invoke(app, ["devices", "--usb-backend", "virtual", "--json"])
    assert result.exit_code == 0, result.output
    [falcon] = json.loads(result.output)["falcons"]
    assert falcon["product"] == "FALCON HAPTIC" and falcon["firmware_running"] is False and falcon["problem"] is None
