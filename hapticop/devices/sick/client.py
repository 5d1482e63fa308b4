"""A TiM5xx CoLa A client that a cyclic thread polls once per cycle and that never blocks it.

`poll(now_ns)` advances a small state machine by at most one step of socket work:

    DISCONNECTED --(backoff elapsed)--> CONNECTING --(writable)--> STARTING --(last reply)--> STREAMING
          ^                                  |                          |                        |
          +------ fail: refused, closed, reply timeout, sFA, stalled stream (backoff doubles) ----+

Start-up sends one command at a time and waits for its reply (the device keeps at most one
request in flight; `sFA` names no request, so it answers the pending one). Scans are parsed
into arrays the client owns, double-buffered so a telegram that fails half-way never
corrupts the last good scan. All timing uses the `now_ns` passed in (or the injected
clock), so the client runs the same under the wall clock and under a virtual clock.

Never blocking: the address is resolved once in the constructor (not in a cycle), the socket
is non-blocking, `connect` completes in later polls, sends that do not fit wait for the next
poll, and one poll reads at most `max_read_bytes`.
"""

from __future__ import annotations

import enum
import errno
import socket
import time
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

from hapticop.devices.sick import commands, scan
from hapticop.devices.sick.cola import ColaDeviceError, ColaError
from hapticop.devices.sick.commands import Command
from hapticop.devices.sick.scan import ScanHeader
from hapticop.devices.sick.stream import MAX_TELEGRAM, TelegramReader

_SCAN_PREFIXES = (b"sSN LMDscandata ", b"sRA LMDscandata ")


class ClientState(enum.Enum):
    DISCONNECTED = "disconnected"  # no socket; the next attempt waits for the backoff
    CONNECTING = "connecting"  # non-blocking connect in progress
    STARTING = "starting"  # start-up commands, one reply at a time
    STREAMING = "streaming"  # subscribed; scans arrive
    CLOSED = "closed"  # close() was called


class ColaClient:
    """Connects, configures, subscribes and keeps the newest scan; reconnects on any failure.

    Counters: `scans` (parsed), `connects` and `reconnects` (attempts after the first),
    `discarded_bytes` (outside frames), `bad_telegrams` (framed but undecodable, skipped),
    `device_errors` (sFA or a refusing reply), `timeouts` (connect or reply), `stalls`.
    `last_error` says why the last connection ended.

    Watchdogs: `connect_timeout_s` for the handshake, `reply_timeout_s` per start-up reply,
    `first_scan_timeout_s` after subscribing (the device restarts measuring after Run), then
    `stall_periods` scan periods (from the scan frequency in the telegrams) between scans.
    """

    def __init__(
        self,
        host: str,
        port: int = 2112,
        *,
        backoff: tuple[float, float] = (0.1, 2.0),
        clock_ns: Callable[[], int] = time.monotonic_ns,
        points: int = scan.TIM561_POINTS,
        startup: Sequence[Command] | None = None,
        reply_timeout_s: float = 1.0,
        connect_timeout_s: float = 1.0,
        first_scan_timeout_s: float = 2.0,
        stall_periods: float = 3.0,
        scan_period_s: float = 1.0 / 15.0,
        min_range_m: float = scan.MIN_RANGE_M,
        max_read_bytes: int = 256 * 1024,
        max_telegram: int = MAX_TELEGRAM,
        sockets: Callable[[int, int], socket.socket] = socket.socket,
    ):
        if not 0 < backoff[0] <= backoff[1]:
            raise ValueError("backoff must be (first delay, longest delay) with 0 < first <= longest")
        infos = socket.getaddrinfo(host, port, socket.AF_UNSPEC, socket.SOCK_STREAM)  # once, not in a cycle
        self._family, _, _, _, self._address = infos[0]
        self.host, self.port = host, port
        self._sockets = sockets  # socket.socket, or in-memory streams under the virtual clock (devices.memory_stream)
        self.backoff = backoff
        self._clock = clock_ns
        self.points = points
        self.startup: tuple[Command, ...] = tuple(startup) if startup is not None else commands.startup_sequence()
        if not self.startup:
            raise ValueError("the start-up sequence needs at least the subscription")
        self.reply_timeout_ns = int(reply_timeout_s * 1e9)
        self.connect_timeout_ns = int(connect_timeout_s * 1e9)
        self.first_scan_timeout_ns = int(first_scan_timeout_s * 1e9)
        self.stall_periods = stall_periods
        self.nominal_period_ns = int(scan_period_s * 1e9)
        self.min_range_m = min_range_m
        self.max_read_bytes = max_read_bytes

        self.state = ClientState.DISCONNECTED
        self.last_error = ""
        self.header: ScanHeader | None = None  # of the newest scan
        self.scan_host_ns = 0  # poll time at which the newest scan was parsed
        # counters
        self.scans = 0
        self.connects = 0
        self.reconnects = 0
        self.bad_telegrams = 0
        self.device_errors = 0
        self.timeouts = 0
        self.stalls = 0
        self.unexpected_replies = 0
        self.bytes_sent = 0
        self.bytes_received = 0

        self._reader = TelegramReader(max_telegram)
        self._rx = bytearray(64 * 1024)
        self._rx_view = memoryview(self._rx)
        self._tx = bytearray()
        self._sock: socket.socket | None = None
        self._step = 0  # index of the start-up command in flight
        self._deadline_ns = 0  # connect, reply, first-scan or stall deadline, by state
        self._next_attempt_ns: int | None = None  # None: connect at the first poll
        self._delay_ns = int(backoff[0] * 1e9)
        self._failures = 0
        # double buffers: parse into the back pair, swap on success
        self._ranges = [np.full(points, np.nan), np.full(points, np.nan)]
        self._angles = [np.zeros(points), np.zeros(points)]
        self._front = 0
        self._delivered = 0  # scans handed out by latest_scan
        self.scans_this_connection = 0
        self._last_progress_ns = 0  # subscription or newest scan: the stall watchdog counts from here

    # -- the cyclic entry point ------------------------------------------------------------

    def poll(self, now_ns: int | None = None) -> int:
        """Advance the state machine; returns how many new scans this call parsed."""
        now = self._clock() if now_ns is None else now_ns
        if self.state is ClientState.CLOSED:
            return 0
        if self.state is ClientState.DISCONNECTED:
            if self._next_attempt_ns is None or now >= self._next_attempt_ns:
                self._connect(now)
            return 0
        if self.state is ClientState.CONNECTING:
            self._finish_connect(now)
            if self.state is not ClientState.STARTING:
                return 0
        before = self.scans
        try:
            self._flush()
            self._receive(now)
        except OSError as error:
            self._fail(now, f"socket error: {error.strerror or error}")
            return self.scans - before
        if self.state is ClientState.STARTING and now > self._deadline_ns:
            self.timeouts += 1
            self._fail(now, f"no reply to {self.startup[self._step].text!r} within "
                            f"{self.reply_timeout_ns / 1e9:g} s")
        elif self.state is ClientState.STREAMING and now > self._deadline_ns:
            self.stalls += 1
            what = "first scan" if self.scans_this_connection == 0 else "scan"
            self._fail(now, f"stream stalled: no {what} for {(now - self._last_progress_ns) / 1e9:.3f} s")
        return self.scans - before

    def fileno(self) -> int:
        """The socket a caller may wait on for data, while the client reads it each poll
        (starting or streaming); -1 otherwise."""
        if self._sock is None or self.state not in (ClientState.STARTING, ClientState.STREAMING):
            return -1
        return self._sock.fileno()

    # -- results -------------------------------------------------------------------------

    @property
    def ranges_m(self) -> NDArray[np.float64]:
        """The newest scan's ranges (metres, sensor frame, NaN = invalid); the client owns it."""
        return self._ranges[self._front]

    @property
    def angles_rad(self) -> NDArray[np.float64]:
        return self._angles[self._front]

    def latest_scan(self, out_ranges: NDArray[np.floating], out_angles: NDArray[np.floating] | None = None) -> bool:
        """Copy the newest scan into the caller's arrays if it is new since the last call."""
        if self._delivered == self.scans:
            return False
        np.copyto(out_ranges, self._ranges[self._front])
        if out_angles is not None:
            np.copyto(out_angles, self._angles[self._front])
        self._delivered = self.scans
        return True

    @property
    def discarded_bytes(self) -> int:
        return self._reader.discarded_bytes

    def close(self) -> None:
        self._close_socket()
        self.state = ClientState.CLOSED

    def __enter__(self) -> ColaClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- connection ----------------------------------------------------------------------

    def _connect(self, now: int) -> None:
        if self.connects:
            self.reconnects += 1
        self.connects += 1
        sock = self._sockets(self._family, socket.SOCK_STREAM)
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self._sock = sock
        self._reader.reset()
        self._tx.clear()
        self.state = ClientState.CONNECTING
        self._deadline_ns = now + self.connect_timeout_ns
        code = sock.connect_ex(self._address)
        if code not in (0, errno.EINPROGRESS, errno.EALREADY, errno.EWOULDBLOCK):
            self._fail(now, f"connect to {self.host}:{self.port}: {errno.errorcode.get(code, code)}")

    def _finish_connect(self, now: int) -> None:
        """Two syscalls, no select (which cannot watch descriptors above 1023)."""
        assert self._sock is not None
        code = self._sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
        if code:
            self._fail(now, f"connect to {self.host}:{self.port}: {errno.errorcode.get(code, code)}")
            return
        try:
            self._sock.getpeername()
        except OSError:  # ENOTCONN: the handshake is still under way
            if now > self._deadline_ns:
                self.timeouts += 1
                self._fail(now, f"connect to {self.host}:{self.port}: no answer within "
                                f"{self.connect_timeout_ns / 1e9:g} s")
            return
        self.state = ClientState.STARTING
        self._step = 0
        self.scans_this_connection = 0
        self._send_step(now)

    def _fail(self, now: int, reason: str) -> None:
        """Close, and schedule the next attempt with exponential backoff."""
        self.last_error = reason
        self._close_socket()
        self.state = ClientState.DISCONNECTED
        self._failures += 1
        self._next_attempt_ns = now + self._delay_ns
        self._delay_ns = min(self._delay_ns * 2, int(self.backoff[1] * 1e9))

    def _close_socket(self) -> None:
        if self._sock is not None:
            try:
                self._sock.close()
            except OSError:
                pass
            self._sock = None

    # -- bytes in and out ----------------------------------------------------------------

    def _send_step(self, now: int) -> None:
        self._tx += self.startup[self._step].request
        self._deadline_ns = now + self.reply_timeout_ns
        self._flush()

    def _flush(self) -> None:
        if self._tx and self._sock is not None:
            try:
                sent = self._sock.send(self._tx)
            except BlockingIOError:
                return
            del self._tx[:sent]
            self.bytes_sent += sent

    def _receive(self, now: int) -> None:
        budget = self.max_read_bytes
        while budget > 0 and self._sock is not None:
            try:
                count = self._sock.recv_into(self._rx_view, min(budget, len(self._rx)))
            except (BlockingIOError, InterruptedError):
                return
            if count == 0:
                self._fail(now, "connection closed by the scanner")
                return
            budget -= count
            self.bytes_received += count
            self._reader.feed(self._rx_view[:count])
            for body in self._reader:
                self._handle(now, body)
                if self._sock is None:
                    return

    def _handle(self, now: int, body: bytes) -> None:
        if body.startswith(_SCAN_PREFIXES):
            self._take_scan(now, body)
            return
        if self.state is not ClientState.STARTING:
            self.unexpected_replies += 1
            return
        command = self.startup[self._step]
        try:
            reply = commands.parse_reply(body, command.text)
        except ColaDeviceError as error:
            self.device_errors += 1
            self._fail(now, str(error))
            return
        except ColaError:
            self.bad_telegrams += 1
            return
        if (reply.kind, reply.name) != command.reply:
            if reply.kind != b"sMA":  # "accepted, result follows" is not the result
                self.unexpected_replies += 1
            return
        try:
            command.check(reply)
        except ColaError as error:
            self.device_errors += 1
            self._fail(now, str(error))
            return
        self._step += 1
        if self._step < len(self.startup):
            self._send_step(now)
        else:
            self.state = ClientState.STREAMING
            self._last_progress_ns = now
            self._deadline_ns = now + self.first_scan_timeout_ns

    def _take_scan(self, now: int, body: bytes) -> None:
        back = 1 - self._front
        try:
            header = scan.parse_scan(body, self._ranges[back], self._angles[back], min_range_m=self.min_range_m)
        except ColaError:
            self.bad_telegrams += 1
            return
        self._front = back
        self.header = header
        self.scans += 1
        self.scan_host_ns = now
        if self.state is ClientState.STREAMING:
            self.scans_this_connection += 1
            self._last_progress_ns = now
            if self._failures:
                self._failures = 0
                self._delay_ns = int(self.backoff[0] * 1e9)
            period = self.nominal_period_ns
            if header.scan_frequency:
                period = int(1e11 / header.scan_frequency)
            self._deadline_ns = now + int(self.stall_periods * period)
