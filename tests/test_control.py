"""The control channel: a Unix socket, one JSON line in and one out, owner only."""

from __future__ import annotations

import json
import os
import socket
import stat
from pathlib import Path

import pytest

from hapticop.runtime import control
from hapticop.runtime.control import ControlError, ControlServer, request, socket_path


@pytest.fixture
def sock(tmp_path) -> Path:
    # AF_UNIX paths are limited to 107 bytes; pytest's tmp_path can be long.
    path = tmp_path / "run" / "s.sock"
    if len(str(path)) > 100:  # pragma: no cover - only on unusual temp dirs
        pytest.skip("temporary directory path too long for a Unix socket")
    return path


def echo(message: dict) -> dict:
    return {"ok": True, "echo": message}


def raw(path: Path, data: bytes) -> dict:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client:
        client.settimeout(5)
        client.connect(str(path))
        client.sendall(data)
        client.shutdown(socket.SHUT_WR)
        reply = b""
        while chunk := client.recv(65536):
            reply += chunk
    return json.loads(reply)


def test_round_trip(sock):
    with ControlServer(sock, echo) as server:
        assert server.running
        assert request(sock, {"command": "status", "n": [1, 2]}) == {
            "ok": True, "echo": {"command": "status", "n": [1, 2]}}
        assert request(str(sock), {"command": "again"})["echo"] == {"command": "again"}  # one request per connection
    assert not sock.exists()


def test_handler_exception_becomes_ok_false(sock):
    def broken(message: dict) -> dict:
        raise ValueError(f"cannot {message['command']}")

    with ControlServer(sock, broken):
        assert request(sock, {"command": "explode"}) == {"ok": False, "error": "cannot explode"}
        # The server survives its handler's failures.
        assert request(sock, {"command": "again"}) == {"ok": False, "error": "cannot again"}


def test_handler_reply_that_is_not_a_mapping(sock):
    with ControlServer(sock, lambda message: ["not", "a", "dict"]):
        reply = request(sock, {})
    assert reply["ok"] is False and "list" in reply["error"]


def test_malformed_json_becomes_ok_false(sock):
    with ControlServer(sock, echo):
        reply = raw(sock, b"{not json\n")
        assert reply["ok"] is False and "not JSON" in reply["error"]
        reply = raw(sock, b"[1, 2]\n")
        assert reply["ok"] is False and "object" in reply["error"]
        reply = raw(sock, b"\xff\xfe\n")
        assert reply["ok"] is False
        assert raw(sock, b'{"a": 1}')["echo"] == {"a": 1}  # the end of the stream ends the line too


def test_oversized_request_is_refused(sock, monkeypatch):
    monkeypatch.setattr(control, "MAX_REQUEST_BYTES", 1000)
    with ControlServer(sock, echo):
        reply = raw(sock, b'{"a": "' + b"x" * 5000 + b'"}\n')
        assert reply["ok"] is False and "larger than 1000 bytes" in reply["error"]
        with pytest.raises(ControlError, match="larger than"):
            request(sock, {"a": "x" * 5000})


def test_socket_is_owner_only(sock):
    with ControlServer(sock, echo):
        assert stat.S_ISSOCK(os.stat(sock).st_mode)
        assert stat.S_IMODE(os.stat(sock).st_mode) == 0o600
        assert stat.S_IMODE(os.stat(sock.parent).st_mode) == 0o700  # created by the server


def test_other_users_are_refused(sock, monkeypatch):
    stranger = os.geteuid() + 4242
    monkeypatch.setattr(control, "peer_uid", lambda connection: stranger)
    with ControlServer(sock, echo):
        reply = raw(sock, b'{"command": "status"}\n')
    assert reply["ok"] is False and "permission denied" in reply["error"] and str(stranger) in reply["error"]


def test_second_server_at_the_same_path_is_refused(sock):
    with ControlServer(sock, echo):
        with pytest.raises(ControlError, match="already running") as caught:
            ControlServer(sock, echo).start()
        assert str(sock) in str(caught.value)
        assert request(sock, {"still": "there"})["ok"] is True  # the first one is unharmed


def test_stale_socket_is_replaced(sock):
    sock.parent.mkdir(mode=0o700)
    dead = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    dead.bind(str(sock))
    dead.close()  # a socket file with no one behind it, as a killed process leaves
    assert sock.exists()
    with ControlServer(sock, echo):
        assert request(sock, {"n": 1})["echo"] == {"n": 1}


def test_a_file_that_is_not_a_socket_is_not_replaced(sock):
    sock.parent.mkdir(mode=0o700)
    sock.write_text("precious")
    with pytest.raises(ControlError, match="not a socket"):
        ControlServer(sock, echo).start()
    assert sock.read_text() == "precious"


def test_stop_leaves_a_newer_servers_socket(sock):
    first = ControlServer(sock, echo).start()
    sock.unlink()  # e.g. removed by hand, and a new system started at the same path
    with ControlServer(sock, lambda message: {"ok": True, "who": "second"}):
        first.stop()
        assert request(sock, {})["who"] == "second"


def test_client_error_when_nothing_runs(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", str(tmp_path))
    with pytest.raises(ControlError) as caught:
        request("hallway", {"command": "status"})
    assert str(caught.value) == (
        f"no hapticop system 'hallway' is running (no socket at {tmp_path}/hapticop/hallway.sock)"
    )
    with pytest.raises(ControlError, match=f"no hapticop system at {tmp_path}/x.sock is running"):
        request(tmp_path / "x.sock", {})


def test_client_error_on_a_stale_socket(sock):
    sock.parent.mkdir(mode=0o700)
    dead = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    dead.bind(str(sock))
    dead.close()
    with pytest.raises(ControlError, match="is running .*nothing listens"):
        request(sock, {})


def test_socket_path_rules(monkeypatch):
    monkeypatch.setenv("XDG_RUNTIME_DIR", "/run/user/1000")
    assert socket_path("hallway") == Path("/run/user/1000/hapticop/hallway.sock")
    assert socket_path("./hallway.sock") == Path("hallway.sock")
    assert socket_path("hallway.sock") == Path("hallway.sock")
    assert socket_path("/srv/x/hallway") == Path("/srv/x/hallway")

    monkeypatch.delenv("XDG_RUNTIME_DIR")
    monkeypatch.setattr(os, "geteuid", lambda: 0)
    assert socket_path("hallway") == Path("/run/hapticop/hallway.sock")
    monkeypatch.setattr(os, "geteuid", lambda: 1234)
    assert socket_path("hallway") == Path("/tmp/hapticop-1234/hallway.sock")

    monkeypatch.setenv("XDG_RUNTIME_DIR", "")  # set but empty counts as unset
    assert socket_path("hallway") == Path("/tmp/hapticop-1234/hallway.sock")
    with pytest.raises(ControlError):
        socket_path("")
