"""The live view: the recorder's channels served over Foxglove's WebSocket protocol, thinned for display.

A `LiveServer` is an output like the MCAP file (`recording.outputs`): the recorder hands it the
same channels and batches, and it forwards at most `rate_hz` messages a second per channel to the
clients of `live_gate.Gate`, whose thread serves them in the recorder's process, never on a
real-time loop. Each message goes out with the loop's own stamp as its time, so plots and frames
line up as in a recording; a client that falls behind loses the oldest messages, never the recording.

The protocol has no authentication, and the SDK's server offers no hook to add one, so no SDK
server runs: the gate is the live view's one socket, and it lets a client in only with the run's
token (`?token=` in its URL), written owner-only in the run directory (docs/security.md). With a
certificate and key (`tls_cert`, `tls_key`) it speaks only `wss://`, so neither the streams nor the
token are readable on the way. `exposure` says at start who can reach the address when it is more
than loopback. The messages themselves come encoded: the streams' arrays (`arrays`), the views'
Foxglove schemas (`scene`, with the SDK's message classes), the log and events as the file has them.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hapticop.recording import arrays
from hapticop.recording.live_gate import Gate, new_token, write_token
from hapticop.recording.live_protocol import Advertised
from hapticop.recording.mcapfile import LOG_TOPIC, StreamInfo, topic_of

DEFAULT_PORT = 8765
DEFAULT_HOST = "127.0.0.1"  # this machine only, by default
DEFAULT_RATE_HZ = 30.0
NEEDED = (("foxglove", "foxglove-sdk"), ("websockets", "websockets"))  # the `[foxglove]` extra: modules, packages


class LiveViewUnavailable(RuntimeError):
    """The `[foxglove]` extra is not installed, or the server could not listen."""


@dataclass(frozen=True)
class LiveOptions:
    """Where the live view listens and how often each channel may send (picklable: the recorder
    process receives it)."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT  # 0: any free port (the summary says which)
    rate_hz: float = DEFAULT_RATE_HZ
    tls_cert: str | None = None  # a PEM certificate's file: the server speaks wss:// only
    tls_key: str | None = None  # its PEM PKCS#8 private key's file

    def __post_init__(self) -> None:
        if (self.tls_cert is None) != (self.tls_key is None):
            raise ValueError("the live view's TLS needs both a certificate and its key")
        if not 0 < self.rate_hz <= 1000:
            raise ValueError(f"the live view's rate must be above 0 and at most 1000 Hz, not {self.rate_hz:g}")
        if not 0 <= self.port <= 65535:
            raise ValueError(f"the live view's port must be 0 to 65535, not {self.port}")


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def exposure(options: LiveOptions) -> str | None:
    """Who can watch, said at start when it is more than this machine's users; None on loopback."""
    if is_loopback(options.host):
        return None
    try:
        anywhere = ipaddress.ip_address(options.host).is_unspecified
    except ValueError:
        anywhere = False
    who = (f"anyone who can reach this machine on any of its networks, at port {options.port}" if anywhere
           else f"anyone who can reach {options.host}:{options.port}")
    wire = ("over TLS (wss://)" if options.tls_cert else
            "in the clear (ws://: anyone on the path reads it too; a TLS certificate and key give wss://)")
    return f"warning: the live view serves every stream to {who}, if they hold the run's token, {wire}"


def read_identity(options: LiveOptions) -> tuple[bytes, bytes] | tuple[None, None]:
    """The TLS certificate and key's bytes, or a one-line `LiveViewUnavailable`."""
    if options.tls_cert is None or options.tls_key is None:
        return None, None
    try:
        return Path(options.tls_cert).read_bytes(), Path(options.tls_key).read_bytes()
    except OSError as error:
        raise LiveViewUnavailable(f"the live view cannot read its TLS identity {error.filename}: "
                                  f"{error.strerror}") from None


def require_sdk() -> None:
    """Fail early, in one line, when the `[foxglove]` extra is missing (the SDK for the views' schemas,
    `websockets` for the protocol)."""
    import importlib

    for module, package in NEEDED:
        try:
            importlib.import_module(module)
        except ImportError as missing:
            raise LiveViewUnavailable(f"the live view needs {package}: pip install 'hapticop[foxglove]'") from missing


@dataclass
class _Live:
    """One channel and when it may send next."""

    id: int
    prefix: bytes = b""  # a stream channel's protobuf prefix (`arrays`)
    thinned: bool = True  # not the log (events, each its own) nor a tapped slot (read at the display rate already)
    next_ns: int = 0  # a view's channel: the next message's earliest stamp
    period: int = -1  # a stream's channel: the last display period a sample was sent in


class LiveServer:
    """Foxglove's WebSocket protocol, served by the gate, fed as a recorder output."""

    def __init__(self, options: LiveOptions, name: str = "hapticop", run_dir: Path | None = None):
        require_sdk()
        self.options = options
        self.period_ns = int(1e9 / options.rate_hz)
        cert, key = read_identity(options)
        where = f"{options.host}:{options.port}"
        token = new_token()
        try:
            self.gate = Gate(options.host, options.port, token, name,
                             (cert, key) if cert is not None and key is not None else None)
        except (OSError, ValueError) as error:
            raise LiveViewUnavailable(f"the live view cannot listen on {where}: {error}") from error
        scheme = "wss" if cert else "ws"
        self.public_address = f"{scheme}://{options.host}:{self.gate.port}"  # the port chosen when asked for any (0)
        self.address = f"{self.public_address}/?token={token}"  # what a client opens
        try:
            self.token_file = write_token(run_dir, self.gate.port, token) if run_dir is not None else None
        except OSError as error:
            self.stop()
            raise LiveViewUnavailable(f"the live view cannot write its token in {run_dir}: {error.strerror}") from None
        self._schemas: list[tuple[str, str, bytes]] = []
        self._channels: list[_Live] = []
        self.sent = 0

    def schema(self, name: str, encoding: str, data: bytes) -> int:
        self._schemas.append((name, encoding, bytes(data)))
        return len(self._schemas)

    def channel(self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str]) -> int:
        name, encoding, data = self._schemas[schema_id - 1] if schema_id else ("", "", b"")
        id_ = len(self._channels) + 1
        self._channels.append(_Live(id_, thinned=topic != LOG_TOPIC))
        self.gate.advertise(Advertised(id_, topic, message_encoding, name, encoding, data, dict(metadata)))
        return id_

    def stream_channel(self, info: StreamInfo, thinned: bool = True) -> int:
        """A stream's channel; `thinned=False` for samples already taken at the display rate (`observe.taps`)."""
        schema = self.schema(arrays.schema_name(info.dtype), arrays.SCHEMA_ENCODING, arrays.schema_data(info.dtype))
        id_ = self.channel(topic_of(info.name), arrays.MESSAGE_ENCODING, schema, info.metadata())
        self._channels[id_ - 1].prefix = arrays.prefix(info.nbytes)
        self._channels[id_ - 1].thinned = thinned
        return id_

    def write(self, channel: int, log_time_ns: int, data: bytes, publish_time_ns: int, sequence: int) -> None:
        live = self._channels[channel - 1]
        if (live.thinned and publish_time_ns < live.next_ns) or not self.gate.subscribed(live.id):
            return
        live.next_ns = publish_time_ns + self.period_ns
        self.gate.send(live.id, int(publish_time_ns), bytes(data))
        self.sent += 1

    def write_samples(self, channel: int, samples: np.ndarray, log_time_ns: int) -> None:
        """The first sample of each display period, with the loop's stamp as its time."""
        live = self._channels[channel - 1]
        if not len(samples) or not self.gate.subscribed(live.id):
            return
        if live.thinned:
            periods = samples["stamp_ns"].astype(np.int64) // self.period_ns
            chosen = np.flatnonzero(np.diff(periods, prepend=live.period) > 0)
            live.period = max(live.period, int(periods[-1]))
        else:
            chosen = range(len(samples))
        for k in chosen:
            self.gate.send(live.id, int(samples["stamp_ns"][k]), live.prefix + samples["payload"][k].tobytes())
        self.sent += len(chosen)

    def stop(self) -> None:
        self.gate.stop()  # the backlog and a goodbye to each client first
