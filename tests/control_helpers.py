"""Talking to a control socket as a careless or hostile client would, and running a real system to talk to."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

from hapticop.composition.lcsm import State
from hapticop.control.client import request
from hapticop.runtime.system import ExitStatus

from .runtime_helpers import compose, pipeline

PATIENCE_S = 10.0  # an answer must come within this (a bound on hangs, not a speed requirement)


def send_raw(path: Path, data: bytes, *, close: bool = True) -> dict:
    """Send `data` as it is and read the one-line reply (closing our side first when `close`)."""
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client:
        client.settimeout(PATIENCE_S)
        client.connect(str(path))
        try:
            client.sendall(data)
            if close:
                client.shutdown(socket.SHUT_WR)
        except (BrokenPipeError, ConnectionResetError):
            pass  # refused before it read everything: the reply says why
        reply = b""
        while b"\n" not in reply and (chunk := client.recv(65536)):
            reply += chunk
    assert reply.endswith(b"\n") and reply.count(b"\n") == 1, reply[:200]
    return json.loads(reply)


def timed_status(path: Path) -> float:
    """Seconds `status` took to answer; fails if it does not answer within PATIENCE_S."""
    started = time.monotonic()
    reply = request(path, {"op": "status"}, timeout=PATIENCE_S)
    assert reply["ok"] is True and "status" in reply, reply
    return time.monotonic() - started


class SlowClients:
    """`count` clients that connect and then send one byte every `every_s` seconds, never a newline."""

    def __init__(self, path: Path, count: int = 3, every_s: float = 0.5):
        self.path, self.count, self.every_s = path, count, every_s
        self.stopping = threading.Event()
        self.threads = [threading.Thread(target=self._trickle, daemon=True) for _ in range(count)]

    def _trickle(self) -> None:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as client:
            client.connect(str(self.path))
            while not self.stopping.wait(self.every_s):
                try:
                    client.send(b" ")
                except OSError:  # the server gave up on us (its deadline), as it should: come back
                    return self._trickle() if not self.stopping.is_set() else None

    def __enter__(self) -> SlowClients:
        for thread in self.threads:
            thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stopping.set()
        for thread in self.threads:
            thread.join(PATIENCE_S)


def flood(path: Path, clients: int = 20, requests: int = 50, message: dict | None = None) -> list[dict]:
    """`clients` threads each sending `requests` requests one after another; every reply, in no order."""
    replies: list[dict] = []
    lock = threading.Lock()

    def client() -> None:
        for _ in range(requests):
            try:
                reply = request(path, message or {"op": "status"}, timeout=PATIENCE_S)
            except Exception as error:  # noqa: BLE001 - recorded, and the test fails on it
                reply = {"client error": str(error)}
            with lock:
                replies.append(reply)

    threads = [threading.Thread(target=client, daemon=True) for _ in range(clients)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(requests * PATIENCE_S)
    return replies


def answered_or_busy(reply: dict) -> bool:
    return reply.get("ok") is True or (reply.get("ok") is False and reply.get("error", "").startswith("busy"))


def while_running(tmp_path: Path, work, text: str | None = None, ready: str = "recorder") -> None:
    """Run a real system (real-time clock, control socket; `text`, or the pipeline) and call
    `work(socket, system)` once its activity `ready` runs; the system stops when `work` returns,
    and whatever `work` raised is raised here."""
    path = tmp_path / "s.sock"
    errors: list[BaseException] = []

    def operator(system) -> None:
        def talk() -> None:
            try:
                deadline = time.monotonic() + 20
                while not (path.exists() and system.state(ready) is State.RUNNING):
                    assert time.monotonic() < deadline, "the system did not start"
                    time.sleep(0.02)
                work(path, system)
            except BaseException as error:  # noqa: BLE001 - handed to the test's thread
                errors.append(error)
            finally:
                system.request_shutdown()
        threading.Thread(target=talk, daemon=True).start()

    result = compose(tmp_path, text or pipeline(), clock="realtime", duration="120s", on_start=operator,
                     control=str(path))
    if errors:
        raise errors[0]
    assert result.outcome.status is ExitStatus.SUCCESS, result.outcome.reasons


def peak_rss_kib() -> int:
    """This process's peak resident size (the system runs in it), from /proc."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0
