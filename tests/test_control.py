"""The control channel: a Unix socket, one JSON line in and one out, owner only."""

from __future__ import annotations

import json
import os
import socket
import stat
from pathlib import Path

import pytest

from hapticop.control import client, server
from hapticop.control.address import ControlError, socket_path
from hapticop.control.client import request
from hapticop.control.server import ControlServer


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
    monkeypatch.setattr(server, "MAX_REQUEST_BYTES", 1000)
    monkeypatch.setattr(client, "MAX_REQUEST_BYTES", 1000)
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
    monkeypatch.setattr(server, "peer_uid", lambda connection: stranger)
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


# -- hostile and careless clients (see also test_control_hostile.py, against a running system) --------


@pytest.mark.parametrize(("data", "error"), [
    (b"[" * 200_000 + b"\n", "nested deeper than 64 levels"),
    (b'{"a": ' + b"[" * 65 + b"]" * 65 + b"}\n", "nested deeper than 64 levels"),
    (b"\n", "empty request"),
    (b"   \r\n", "empty request"),
    (b"", "empty request"),
    (b"[1]\n", "a request is a JSON object"),
    (b'"status"\n', "a request is a JSON object"),
    (b"\x00\xff\xfe garbage\n", "not JSON"),
    (b'{"a": NaN}\n', "NaN is not a number a request may carry"),
    (b'{"a": -Infinity}\n', "-Infinity is not a number a request may carry"),
    (b'{"a": ' + b"9" * 5000 + b"}\n", "an integer of 5000 digits is longer than a request may carry"),
    (b'{"a": -' + b"9" * 1001 + b"}\n", "an integer of 1001 digits is longer than a request may carry"),
    (b'{"a": "\\ud800"}', None),  # a lone surrogate, and no newline: the end of the stream ends it
])
def test_every_bad_request_gets_a_one_line_error_and_the_server_goes_on(sock, data, error):
    from .control_helpers import send_raw

    with ControlServer(sock, echo) as server:
        reply = send_raw(sock, data)
        if error is None:
            assert reply["ok"] is True
        else:
            assert reply["ok"] is False and error in reply["error"], reply
        assert request(sock, {"still": "there"})["echo"] == {"still": "there"}
        assert server.running


def test_nesting_inside_strings_is_not_nesting(sock):
    with ControlServer(sock, echo):
        text = "[" * 1000 + '"\\"{' + "}" * 10
        assert request(sock, {"text": text})["echo"] == {"text": text}


def test_a_request_without_newline_is_answered_at_its_deadline(sock, monkeypatch):
    monkeypatch.setattr(server, "READ_DEADLINE", 0.3)
    with ControlServer(sock, echo):
        from .control_helpers import send_raw

        silent = send_raw(sock, b"", close=False)
        assert silent["ok"] is False and "no complete request within 0.3 s: got nothing" in silent["error"]
        partial = send_raw(sock, b'{"op": "sta', close=False)
        assert partial["ok"] is False and "an incomplete request (11 bytes, no newline)" in partial["error"]


def test_slow_and_idle_clients_do_not_hold_up_the_others(sock, monkeypatch):
    from .control_helpers import SlowClients

    monkeypatch.setattr(server, "READ_DEADLINE", 1.0)
    with ControlServer(sock, echo):
        idle = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(3)]
        try:
            for client in idle:
                client.connect(str(sock))
            with SlowClients(sock, count=3, every_s=0.2):
                for n in range(10):
                    assert request(sock, {"n": n}, timeout=10)["echo"] == {"n": n}
        finally:
            for client in idle:
                client.close()


def test_more_clients_than_it_serves_are_told_busy(sock, monkeypatch):
    monkeypatch.setattr(server, "MAX_CLIENTS", 4)
    with ControlServer(sock, echo):
        idle = [socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) for _ in range(4)]
        try:
            for client in idle:
                client.connect(str(sock))
            reply = request(sock, {"n": 1}, timeout=10)
            assert reply["ok"] is False and reply["error"].startswith("busy: 4 clients are being served")
        finally:
            for client in idle:
                client.close()
        assert request(sock, {"n": 2}, timeout=10)["echo"] == {"n": 2}  # room again


def test_a_flood_gets_an_answer_or_busy_for_every_request(sock):
    from .control_helpers import answered_or_busy, flood

    with ControlServer(sock, echo) as server:
        replies = flood(sock, clients=20, requests=50, message={"op": "status"})
        assert len(replies) == 1000
        assert all(answered_or_busy(reply) for reply in replies), [r for r in replies if not answered_or_busy(r)][:3]
        assert server.running and request(sock, {"n": 3})["echo"] == {"n": 3}


def test_a_handler_that_recurses_without_end_does_not_end_the_server(sock):
    def recursive(message: dict) -> dict:
        return recursive(message)

    with ControlServer(sock, recursive):
        assert request(sock, {})["ok"] is False
        assert request(sock, {})["ok"] is False
