"""A TiM561 on loopback: a TCP server that gives one client at a time a `TiMDevice` and streams its scans.

The driver under test talks to it over a real socket, so framing, partial reads, reconnects
and resynchronisation run the same code paths as against the scanner. What the device answers
and what its scans hold is `device_model.TiMDevice`'s; this module is the network side: the
connection, which scans go out and when, and the faults a cable or a busy device cause.

Two ways to run it, one code path (`step`):

* stepped: `step(now_ns)` accepts, answers pending commands and sends the scans due at the
  simulated time `now_ns`, without a thread; a virtual-clock runtime (or a test) calls it
  between client polls, so every run is the same;
* threaded: `start()` runs `step(clock_ns())` on a daemon thread that sleeps in a selector
  until a socket is ready or the next scan is due; `stop()` ends it.

Faults for tests: `drop_connection`, `unplug`, `stall`, `inject_garbage`, `mute`.
"""

from __future__ import annotations

import math
import selectors
import socket
import struct
import threading
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.sick.device_model import TiMDevice
from hapticop.devices.sick.stream import TelegramReader


class TiMSimulator:
    """One client at a time, like docs/devices/sick-tim561.md advise (a second connection is closed at once)."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        ranges_m: Callable[[int], NDArray[np.floating]] | None = None,
        noise_std_m: float = 0.0,
        rng: np.random.Generator | None = None,
        clock_ns: Callable[[], int] = time.monotonic_ns,
        scan_rate_hz: float = 15.0,
        serial_number: int = 0x1078AAA,
        device_name: str = "not defined",
        firmware: str = "V2.51-21.08.15",
        uptime_us: int = 1_073_560_940,
        telegram_counter: int = 0x3E22,
        tx_delay_us: int = 5000,
        max_range_m: float = 10.0,
        max_catchup: int = 15,
        max_backlog: int = 1 << 20,
        sockets: Callable[[int, int], socket.socket] = socket.socket,
    ):
        self.device = TiMDevice(
            ranges_m=ranges_m, noise_std_m=noise_std_m, rng=rng, scan_rate_hz=scan_rate_hz,
            serial_number=serial_number, device_name=device_name, firmware=firmware, uptime_us=uptime_us,
            telegram_counter=telegram_counter, tx_delay_us=tx_delay_us, max_range_m=max_range_m,
        )
        # socket.socket, or in-memory streams under the virtual clock (devices.memory_stream)
        self._listener = sockets(socket.AF_INET, socket.SOCK_STREAM)
        self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._listener.bind((host, port))
        self._listener.listen(4)
        self._listener.setblocking(False)
        self.host, self.port = self._listener.getsockname()[:2]
        self._clock = clock_ns
        self.max_catchup, self.max_backlog = max_catchup, max_backlog

        # connection state
        self._conn: socket.socket | None = None
        self._reader = TelegramReader()
        self._out = bytearray()
        self._last_sent_k = -1
        # faults
        self._stall_until: float | None = None
        self._garbage = bytearray()
        self.unplugged = False
        # counters
        self.scans_sent = 0
        self.scans_dropped = 0
        self.connections = 0
        self.refused_connections = 0
        self.bytes_sent = 0
        self.bytes_received = 0
        # threaded mode (its wake-up pair made by `start`: a stepped simulator has no socket of its own)
        self._lock = threading.RLock()
        self._thread: threading.Thread | None = None
        self._stopping = threading.Event()
        self._wake: tuple[socket.socket, socket.socket] | None = None

    # -- the device's clock and scans, as the tests read them ---------------------------------

    @property
    def epoch_ns(self) -> int | None:
        return self.device.epoch_ns

    @property
    def commands(self) -> int:
        """Requests the device answered (or refused)."""
        return self.device.commands

    def scan_index(self, t_ns: int) -> int:
        return self.device.scan_index(t_ns)

    def scan_time_ns(self, k: int) -> int:
        return self.device.scan_time_ns(k)

    def scan_telegram(self, k: int, command_type: str = "sSN") -> bytes:
        return self.device.scan_telegram(k, command_type)

    # -- stepping ----------------------------------------------------------------------------

    def step(self, now_ns: int) -> int:
        """Accept, answer pending commands, send the scans due at now_ns; returns bytes sent."""
        if self._thread is not None:
            raise RuntimeError("the simulator runs on its own thread: stop() it before stepping by hand")
        return self._step(now_ns)

    def _step(self, now_ns: int) -> int:
        with self._lock:
            sent_before = self.bytes_sent
            self.device.advance(now_ns)
            self._read()  # first, so a closed connection is noticed before a new one is refused
            if self._accept():
                self._read()
            if self._conn is not None:
                if self._garbage:
                    self._out += self._garbage
                    self._garbage.clear()
                self._stream(now_ns)
                self._flush()
            return self.bytes_sent - sent_before

    def _accept(self) -> bool:
        accepted = False
        while True:
            try:
                conn, _ = self._listener.accept()
            except (BlockingIOError, InterruptedError):
                return accepted
            if self._conn is not None or self.unplugged:
                self.refused_connections += 1
                conn.close()
                continue
            conn.setblocking(False)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._conn = conn
            self.connections += 1
            self._reader.reset()
            self._out.clear()
            self.device.open_session()
            accepted = True

    def _read(self) -> None:
        while self._conn is not None:
            try:
                data = self._conn.recv(65536)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                data = b""
            if not data:
                self._disconnect()
                return
            self.bytes_received += len(data)
            for body in self._reader.push(data):
                self._answer(body)

    def _answer(self, body: bytes) -> None:
        device = self.device
        was_subscribed = device.subscribed
        reply = device.answer(body)
        if device.subscribed and not was_subscribed:
            self._last_sent_k = device.scan_index(device.now_ns)  # the next scan is the first one sent
        if reply:
            self._out += reply

    def _flush(self) -> None:
        while self._out and self._conn is not None:
            try:
                sent = self._conn.send(self._out)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self._disconnect()
                return
            del self._out[:sent]
            self.bytes_sent += sent
        if self.device.rebooting and not self._out:
            self._disconnect()

    def _disconnect(self) -> None:
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        self._out.clear()
        self.device.close_session()

    def _stream(self, now_ns: int) -> None:
        k_now = self.device.scan_index(now_ns)
        first = max(self._last_sent_k + 1, k_now - self.max_catchup + 1)
        self._last_sent_k = max(self._last_sent_k, k_now)  # scans nobody listens to are gone
        if self._stall_until is not None:
            if now_ns < self._stall_until:
                return
            self._stall_until = None
        if not self.device.streaming:
            return
        for k in range(first, k_now + 1):
            if len(self._out) > self.max_backlog:
                self.scans_dropped += 1
                continue
            self._out += self.device.scan_telegram(k, "sSN")
            self.scans_sent += 1

    # -- faults ----------------------------------------------------------------------------

    def drop_connection(self, reset: bool = False) -> None:
        """Close the client's connection now (with `reset`, abortively: the peer sees RST)."""
        with self._lock:
            if self._conn is not None and reset:
                self._conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            self._disconnect()

    def stall(self, until_ns: int | None = None) -> None:
        """Stop sending scans (the connection stays up) until `until_ns`, or until `resume()`."""
        with self._lock:
            self._stall_until = math.inf if until_ns is None else until_ns

    def resume(self) -> None:
        with self._lock:
            self._stall_until = None

    def inject_garbage(self, data: bytes = b"\xff\x00noise\x03\x02broken frame") -> None:
        """Send these bytes before the next telegram (the default also holds a broken frame)."""
        with self._lock:
            self._garbage += data

    def unplug(self, on: bool = True) -> None:
        """Cable pulled: the connection drops and new ones are refused until plugged back."""
        with self._lock:
            self.unplugged = on
            if on:
                self._disconnect()

    def set_fault(self, fault: str) -> None:
        """A lasting fault by name: 'unplugged', 'stall', or 'none' to clear them ('garbage' is
        noise the caller injects as long as it lasts, so it only clears the others here)."""
        self.unplug(fault == "unplugged")
        if fault == "stall":
            self.stall()
        else:
            self.resume()

    def mute(self, on: bool = True) -> None:
        """Ignore commands (no reply at all), so the client's reply timeout fires."""
        with self._lock:
            self.device.muted = on

    @property
    def connected(self) -> bool:
        return self._conn is not None

    def filenos(self) -> tuple[int, ...]:
        """The sockets a stepped simulator has work on when they are readable: a client
        connecting, a command arriving."""
        conn = self._conn
        fds = (self._listener.fileno(),) if conn is None else (self._listener.fileno(), conn.fileno())
        return tuple(fd for fd in fds if fd >= 0)  # in-memory streams have none

    # -- threaded mode ---------------------------------------------------------------------

    def start(self) -> TiMSimulator:
        """Serve in real time on a daemon thread, using `clock_ns` for the scan schedule."""
        if self._thread is not None:
            raise RuntimeError("already started")
        self._stopping.clear()
        self._wake = socket.socketpair()
        for end in self._wake:
            end.setblocking(False)
        self._thread = threading.Thread(target=self._serve, name=f"tim561-sim:{self.port}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        thread = self._thread
        if thread is None:
            return
        self._stopping.set()
        wake_r, wake_w = self._wake  # type: ignore[misc]
        try:
            wake_w.send(b"x")
        except OSError:
            pass
        thread.join(timeout=5.0)
        self._thread = self._wake = None
        wake_r.close()
        wake_w.close()

    def _serve(self) -> None:
        wake_r = self._wake[0]  # type: ignore[index]
        selector = selectors.DefaultSelector()
        selector.register(self._listener, selectors.EVENT_READ)
        selector.register(wake_r, selectors.EVENT_READ)
        watched: tuple[socket.socket, int] | None = None  # (socket, events) registered
        try:
            while not self._stopping.is_set():
                now = self._clock()
                self._step(now)
                with self._lock:
                    conn = self._conn
                    events = selectors.EVENT_READ | (selectors.EVENT_WRITE if self._out else 0)
                    due = None
                    if self.device.streaming:
                        due = self.device.scan_time_ns(self._last_sent_k + 1)
                if watched is not None and (conn is not watched[0] or events != watched[1]):
                    try:
                        selector.unregister(watched[0])
                    except (KeyError, ValueError):
                        pass
                    watched = None
                if conn is not None and watched is None:
                    selector.register(conn, events)
                    watched = (conn, events)
                timeout = 0.1 if due is None else min(max((due - self._clock()) / 1e9, 0.0), 0.1)
                for key, _ in selector.select(timeout):
                    if key.fileobj is wake_r:
                        try:
                            wake_r.recv(64)
                        except OSError:
                            pass
        finally:
            selector.close()

    def close(self) -> None:
        self.stop()
        with self._lock:
            self._disconnect()
            self._listener.close()

    def __enter__(self) -> TiMSimulator:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
